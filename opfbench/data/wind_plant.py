"""The stated wind turbine and its power from hourly weather (windpowerlib).

Turbine: Enercon E-82/2350 (2350 kW, rotor 82 m) from windpowerlib's bundled
turbine library (read offline from the package), hub height 78 m. Wind speed at hub
height by the logarithmic profile law from 10 m with roughness length 0.1 m (farmland
with scattered obstacles); air density at hub height by the barometric formula from
station pressure and 2-m temperature (linear gradient −6.5 K/km); the power curve is
density-corrected (IEC 61400-12 method of windpowerlib).
"""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd


@dataclass(frozen=True)
class TurbineSpec:
    """A turbine of windpowerlib's bundled library, placed at ``hub_height_m``."""

    turbine_type: str = "E-82/2350"
    hub_height_m: float = 78.0
    roughness_length_m: float = 0.1
    wind_measurement_height_m: float = 10.0
    temperature_height_m: float = 2.0


#: The turbine whose output the embedded hourly wind series gives.
TURBINE = TurbineSpec()


def turbine_rating_kw(spec: TurbineSpec = TURBINE) -> float:
    """Nominal power in kW of ``spec`` from windpowerlib's bundled turbine data."""
    from windpowerlib import WindTurbine

    return WindTurbine(hub_height=spec.hub_height_m, turbine_type=spec.turbine_type).nominal_power / 1e3


def wind_power_kw(weather: pd.DataFrame, spec: TurbineSpec = TURBINE) -> pd.Series:
    """Electrical power in kW of one ``spec`` turbine for gap-free weather with columns
    ``wind_speed_ms`` (m/s at 10 m), ``temp_air_c`` (°C at 2 m), ``pressure_hpa``."""
    from windpowerlib import ModelChain, WindTurbine

    turbine = WindTurbine(hub_height=spec.hub_height_m, turbine_type=spec.turbine_type)
    mc_weather = pd.DataFrame(
        {
            ("wind_speed", spec.wind_measurement_height_m): weather["wind_speed_ms"],
            ("temperature", spec.temperature_height_m): weather["temp_air_c"] + 273.15,
            ("pressure", 0.0): weather["pressure_hpa"] * 100.0,
            ("roughness_length", 0.0): spec.roughness_length_m,
        },
        index=weather.index,
    )
    chain = ModelChain(
        turbine,
        wind_speed_model="logarithmic",
        density_model="barometric",
        temperature_model="linear_gradient",
        power_output_model="power_curve",
        density_correction=True,
    ).run_model(mc_weather)
    return (chain.power_output / 1e3).rename("wind_power_kw")
