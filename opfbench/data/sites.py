"""Measurement sites of the embedded time series (WGS84 degrees, metres above sea level)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Site:
    """A location: latitude/longitude in degrees (north/east positive), altitude in m,
    and the IANA time zone of its local clock."""

    name: str
    latitude: float
    longitude: float
    altitude_m: float
    tz: str

    def __str__(self) -> str:
        return f"{self.name} ({self.latitude} N, {self.longitude} E, {self.altitude_m:g} m)"


#: BSRN station Payerne (MeteoSwiss aerological station, Switzerland); local clock CET/CEST.
PAYERNE = Site("Payerne", 46.8123, 6.9422, 491.0, "Europe/Zurich")

#: DWD test reference year region 04 representative station Potsdam (WMO 10379): 52°23'N 13°04'E, 81 m.
POTSDAM = Site("Potsdam", 52.3833, 13.0667, 81.0, "Etc/GMT-1")
