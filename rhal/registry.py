"""Choose a driver from a robot URL.

The scheme of the URL names the driver; the query string carries options, so one string in a
setting or a database row describes a robot: ``sim://?arena=square&max_linear=0.3``.
Drivers are imported only when used, so a missing optional library only matters to the robots
that need it.
"""

from __future__ import annotations

import importlib
import math
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from rhal.base import Robot
from rhal.errors import DriverUnavailableError, UnknownDriverError

#: URL scheme -> (module, class name) of its driver.
DRIVERS: dict[str, tuple[str, str]] = {
    "sim": ("rhal.sim", "SimRobot"),
    "dtmf": ("rhal.dtmf", "DtmfRobot"),
    "pioneer": ("rhal.pioneer", "PioneerRobot"),
    "pioneer+tcp": ("rhal.pioneer", "PioneerRobot"),
    "nxt": ("rhal.nxt_brick", "NxtRobot"),
    "mavlink": ("rhal.mavlink", "MavlinkRobot"),
    "mavlink+tcp": ("rhal.mavlink", "MavlinkRobot"),
    "mavlink+udp": ("rhal.mavlink", "MavlinkRobot"),
    "can": ("rhal.canbus", "CanRobot"),
}


def connect(url: str, **options: Any) -> Robot:
    """Create the robot for ``url``, not yet opened.

    Options from the URL's query string are merged with ``options``; keyword options win.
    An option the driver does not take raises TypeError, as for any Python call.
    """
    driver = driver_class(url)
    return driver(url, **{**parse_query_options(urlsplit(url).query), **options})


def driver_class(url: str) -> type[Robot]:
    """The driver class for ``url``'s scheme, imported now."""
    scheme = urlsplit(url).scheme.lower()
    if scheme not in DRIVERS:
        known = ", ".join(f"{name}://" for name in sorted(DRIVERS))
        raise UnknownDriverError(f"no robot driver for {url!r}; known schemes: {known}")
    return _load_driver(scheme)


def parse_query_options(query: str) -> dict[str, Any]:
    """``"a=1&b=0.5&c=x&d=true"`` -> ``{"a": 1, "b": 0.5, "c": "x", "d": True}``."""
    return {key: _parse_value(value) for key, value in parse_qsl(query, keep_blank_values=True)}


def _parse_value(text: str) -> Any:
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        number = float(text)
    except ValueError:
        return text
    # "nan" and "inf" parse as floats but are never a meaningful option value.
    return number if math.isfinite(number) else text


def _load_driver(scheme: str) -> type[Robot]:
    module_name, class_name = DRIVERS[scheme]
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        missing = exc.name or str(exc)
        raise DriverUnavailableError(
            f"the {scheme}:// driver needs {missing!r}, which is not installed: {exc}"
        ) from exc
    return getattr(module, class_name)
