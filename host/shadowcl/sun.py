"""The sun as directional lights (extra ``sun``): positions from pvlib's NREL SPA, for sun-hours studies.

>>> suns = sc.sun_lights(48.85, 2.35, start="2026-06-21", end="2026-06-22", step="1h")
>>> hours = sc.shadow_counts(scene, suns, sensors, weights=...)           # see shadowcl.cli sun-hours

Scene axes: ``up`` (default +y, the scene files' up) and ``north`` (default -z, so that east is +x:
east = north x up). A sun at elevation e and azimuth a (degrees clockwise from north, as pvlib gives
it) is towards ``cos e (cos a north + sin a east) + sin e up``; its light travels the other way. The
elevation is pvlib's ``apparent_elevation`` (with atmospheric refraction), and a sun counts as up when
it is above ``min_elevation`` (default 0: its centre above the horizon).
"""

from __future__ import annotations

import numpy as np

from .checks import vector3
from .lights import DirectionalLight

UP = (0.0, 1.0, 0.0)
NORTH = (0.0, 0.0, -1.0)


def sun_times(start, end, step="1h", timezone: str = "UTC"):
    """A pandas ``DatetimeIndex`` from ``start`` (included) to ``end`` (excluded) every ``step``
    (a pandas offset such as ``"1h"``, ``"15min"``), in ``timezone`` when the times carry none."""
    pd, _ = _sun_extra()

    try:
        step = pd.Timedelta(step)
    except (TypeError, ValueError) as error:
        raise ValueError(f"step: not a time step ({error})") from None
    if not step > pd.Timedelta(0):
        raise ValueError(f"step: must be positive, got {step}")
    try:
        # start and end localised first, then stepped as aware times: naive times stepped then localised
        # would hit the clock change's nonexistent (spring) and ambiguous (autumn) local times
        start, end = (_aware(pd.Timestamp(time), timezone) for time in (start, end))
        times = pd.date_range(start, end, freq=step, inclusive="left")
    except (TypeError, ValueError) as error:
        raise ValueError(f"start, end: not a period in timezone {timezone!r} ({error})") from None
    if len(times) == 0:
        raise ValueError(f"start, end: the period from {start} to {end} is empty")
    return times


def _aware(time, timezone: str):
    """``time`` in ``timezone`` when it carries none (a naive time on a clock change: the later one)."""
    if time.tz is not None:
        return time
    try:
        return time.tz_localize(timezone, nonexistent="shift_forward", ambiguous=False)
    except KeyError:                                     # zoneinfo's and pytz's unknown-zone errors
        raise ValueError(f"timezone: unknown time zone {timezone!r}") from None


def sun_positions(latitude: float, longitude: float, times, altitude: float = 0.0):
    """pvlib's solar position (NREL SPA) at ``times`` (a ``DatetimeIndex``; naive times are UTC):
    a DataFrame with ``apparent_elevation``, ``elevation``, ``azimuth`` in degrees."""
    pd, solarposition = _sun_extra()

    latitude, longitude = _site(latitude, longitude)
    if not isinstance(times, pd.DatetimeIndex):
        raise TypeError(f"times: expected a pandas DatetimeIndex, got {type(times).__name__}")
    if len(times) == 0:
        raise ValueError("times: empty")
    if times.tz is None:
        times = times.tz_localize("UTC")
    return solarposition.get_solarposition(times, latitude, longitude, altitude=altitude, method="nrel_numpy")


def sun_lights(latitude: float, longitude: float, times=None, *, start=None, end=None, step="1h",
               timezone: str = "UTC", altitude: float = 0.0, up=UP, north=NORTH,
               min_elevation: float = 0.0) -> list[DirectionalLight]:
    """The sun at ``times`` as :class:`DirectionalLight`\\ s, those above ``min_elevation`` only.

    ``times`` is a pandas ``DatetimeIndex``, or None with ``start``, ``end`` and ``step``
    (:func:`sun_times`). ``latitude`` in [-90, 90] and ``longitude`` in [-180, 180] degrees;
    ``altitude`` in metres; ``up`` and ``north`` the scene's axes (module docstring).
    """
    elevation, azimuth = sun_angles(latitude, longitude, times, start, end, step, timezone, altitude, min_elevation)
    return [DirectionalLight(d) for d in light_directions(elevation, azimuth, up, north)]


def sun_angles(latitude, longitude, times=None, start=None, end=None, step="1h", timezone="UTC", altitude=0.0,
               min_elevation=0.0) -> tuple[np.ndarray, np.ndarray]:
    """(apparent elevation, azimuth) in degrees of the sun at the times it is above ``min_elevation``."""
    if times is None:
        if start is None or end is None:
            raise ValueError("times: give a DatetimeIndex, or start and end (and step)")
        times = sun_times(start, end, step, timezone)
    position = sun_positions(latitude, longitude, times, altitude)
    up = position["apparent_elevation"].to_numpy() > min_elevation
    return position["apparent_elevation"].to_numpy()[up], position["azimuth"].to_numpy()[up]


def light_directions(elevation, azimuth, up=UP, north=NORTH) -> np.ndarray:
    """(K, 3) unit directions the light travels, for suns at ``elevation`` and ``azimuth`` (degrees)."""
    up = vector3("up", up, nonzero=True)
    north = vector3("north", north, nonzero=True)
    up = up / np.linalg.norm(up)
    north = north - np.dot(north, up) * up
    if not np.linalg.norm(north) > 1e-9:
        raise ValueError("north: must not be parallel to up")
    north /= np.linalg.norm(north)
    east = np.cross(north, up)
    e, a = np.radians(np.asarray(elevation, float))[:, None], np.radians(np.asarray(azimuth, float))[:, None]
    to_sun = np.cos(e) * (np.cos(a) * north + np.sin(a) * east) + np.sin(e) * up
    return -to_sun


def _sun_extra():
    """pandas and pvlib's solarposition, or an ImportError that says which extra brings them."""
    try:
        import pandas
        from pvlib import solarposition
    except ImportError as error:
        raise ImportError(f"sun positions need pvlib and pandas: pip install 'shadowcl[sun]' ({error})") from None
    return pandas, solarposition


def _site(latitude, longitude) -> tuple[float, float]:
    for name, value, limit in (("latitude", latitude, 90), ("longitude", longitude, 180)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            raise TypeError(f"{name}: expected a number of degrees, got {type(value).__name__}")
        if not (np.isfinite(value) and -limit <= value <= limit):
            raise ValueError(f"{name}: must be within ±{limit} degrees, got {value}")
    return float(latitude), float(longitude)
