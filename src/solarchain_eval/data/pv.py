"""Photovoltaic physics: the irradiance cap and the per-node power upper bound (docs/dataset.md)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from pvlib.location import Location

from .cities import City

#: Observed irradiance may exceed the clear-sky model by at most this factor.
CLEAR_SKY_CAP = 1.08
#: Temperature factor limits and reference temperature, °C.
TEMP_FACTOR_MIN, TEMP_FACTOR_MAX, REFERENCE_TEMP_C = 0.78, 1.08, 25.0


def solar_geometry(city: City, times: pd.DatetimeIndex) -> tuple[np.ndarray, np.ndarray]:
    """Clear-sky GHI (W/m², Ineichen) and true solar zenith (degrees) at the city centre.

    Parameters
    ----------
    city : City
        Location; the centre coordinates are used, not the weather grid cell.
    times : pandas.DatetimeIndex
        Time-zone-aware hourly timestamps.
    """
    location = Location(city.latitude, city.longitude, tz=str(times.tz))
    clear_sky = location.get_clearsky(times, model="ineichen")
    position = location.get_solarposition(times)
    return clear_sky["ghi"].to_numpy(dtype=np.float64), position["zenith"].to_numpy(dtype=np.float64)


def capped_irradiance_wm2(
    observed_wm2: np.ndarray, clear_sky_ghi_wm2: np.ndarray, zenith_deg: np.ndarray
) -> np.ndarray:
    """Irradiance used for PV power, W/m².

    Zero when the sun is below the horizon (zenith >= 90°); otherwise the observed shortwave
    radiation, floored at 0 and capped at 1.08 × the clear-sky GHI.
    """
    capped = np.minimum(np.maximum(observed_wm2, 0.0), CLEAR_SKY_CAP * np.maximum(clear_sky_ghi_wm2, 0.0))
    return np.where(zenith_deg >= 90.0, 0.0, capped)


def temperature_factor(temp_coefficient_per_c: float, air_temp_c: np.ndarray) -> np.ndarray:
    """Module temperature derating, clip(1 + γ (T - 25 °C), 0.78, 1.08) (dimensionless)."""
    return np.clip(1 + temp_coefficient_per_c * (air_temp_c - REFERENCE_TEMP_C), TEMP_FACTOR_MIN, TEMP_FACTOR_MAX)


def max_power_w(
    irradiance_wm2: np.ndarray, panel_area_m2: float, efficiency: float, temp_factor: np.ndarray
) -> np.ndarray:
    """Physical upper bound of a node's output, P_max = max(0, I · area · η · f_T), W."""
    return np.maximum(0.0, irradiance_wm2 * panel_area_m2 * efficiency * temp_factor)
