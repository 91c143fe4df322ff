"""The stated PV plant and its AC output from measured weather (pvlib, PVWatts).

Model chain, 1-min steps: solar position (NREL SPA with measured pressure and
temperature) → Perez 1990 transposition (albedo 0.2; Perez returns no sky diffuse
light once the sun is below the horizon) → physical incidence-angle modifier on the
beam part → SAPM cell temperature (open rack, glass/polymer, constant wind speed) →
PVWatts DC → PVWatts system losses → PVWatts inverter clipped at the AC rating.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.data.sites import Site


@dataclass(frozen=True)
class PVPlant:
    """Fixed-tilt PV plant. Powers in kW, angles in degrees (azimuth 180 = south)."""

    dc_rating_kw: float = 10.0
    ac_rating_kw: float = 10.0
    tilt_deg: float = 30.0
    azimuth_deg: float = 180.0
    gamma_pdc_per_c: float = -0.004  # PVWatts DC temperature coefficient, 1/°C
    inverter_eta_nom: float = 0.96  # PVWatts nominal inverter efficiency
    system_losses_pct: float = 14.08  # PVWatts default losses (soiling, wiring, mismatch, ...)
    albedo: float = 0.2
    wind_speed_ms: float = 1.0  # BSRN LR0100 has no wind: constant 1 m/s for cell temperature


#: The plant whose output the embedded 1-min PV series gives.
PV_PLANT = PVPlant()


def pv_ac_power_kw(weather: pd.DataFrame, site: Site, plant: PVPlant = PV_PLANT) -> pd.Series:
    """AC power in kW of ``plant`` at ``site`` for gap-free weather with the columns of
    `opfbench.data.bsrn.WEATHER_UNITS` (W/m², °C, hPa) on a tz-aware index.
    Negative irradiance readings (night-time thermal offset) are taken as zero."""
    import pvlib

    ghi, dni, dhi = (weather[c].clip(lower=0.0) for c in ("ghi_wm2", "dni_wm2", "dhi_wm2"))
    sun = pvlib.solarposition.get_solarposition(
        weather.index,
        site.latitude,
        site.longitude,
        site.altitude_m,
        pressure=weather["pressure_hpa"] * 100.0,
        temperature=weather["temp_air_c"],
    )
    poa = pvlib.irradiance.get_total_irradiance(
        plant.tilt_deg,
        plant.azimuth_deg,
        sun["apparent_zenith"],
        sun["azimuth"],
        dni,
        ghi,
        dhi,
        dni_extra=pvlib.irradiance.get_extra_radiation(weather.index),
        airmass=pvlib.atmosphere.get_relative_airmass(sun["apparent_zenith"]),
        albedo=plant.albedo,
        model="perez",
    ).fillna(0.0)  # Perez is 0/0 (NaN) where the sun is down or DHI is zero: no sky light
    aoi = pvlib.irradiance.aoi(plant.tilt_deg, plant.azimuth_deg, sun["apparent_zenith"], sun["azimuth"])
    effective = poa["poa_direct"] * pvlib.iam.physical(aoi) + poa["poa_diffuse"]
    params = pvlib.temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    cell = pvlib.temperature.sapm_cell(poa["poa_global"], weather["temp_air_c"], plant.wind_speed_ms, **params)
    dc_w = pvlib.pvsystem.pvwatts_dc(effective, cell, plant.dc_rating_kw * 1e3, plant.gamma_pdc_per_c)
    dc_w = dc_w * (1.0 - plant.system_losses_pct / 100.0)
    ac_w = pvlib.inverter.pvwatts(dc_w, plant.ac_rating_kw * 1e3 / plant.inverter_eta_nom, plant.inverter_eta_nom)
    return pd.Series(np.asarray(ac_w) / 1e3, index=weather.index, name="pv_ac_kw")
