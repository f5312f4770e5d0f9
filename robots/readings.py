"""A robot's readings and shown values, as its page shows them."""

import base64


def flatten(readings: dict, prefix: str = "") -> list[tuple[str, object]]:
    rows = []
    for key, value in readings.items():
        if isinstance(value, dict):
            rows.extend(flatten(value, f"{prefix}{key}."))
        else:
            rows.append((f"{prefix}{key}", value))
    return rows


def show_item(name: str, entry: dict) -> dict:
    value = entry["value"]
    item = {"name": name, "run": entry["run"], "value": value, "svg": None}
    if isinstance(value, str) and value.lstrip().startswith(("<svg", "<?xml")):
        # Shown as an image: a browser runs no script from an SVG inside <img>.
        item["svg"] = "data:image/svg+xml;base64," + base64.b64encode(value.encode()).decode()
    return item


def sensor_rows(sensors: dict, units: dict) -> list[tuple[str, object, str]]:
    """Name, value and unit of each reading; a link error is not a reading (see link_error)."""
    readings = {k: v for k, v in sensors.items() if k != "error"}
    return [(name, value, units.get(name, "")) for name, value in flatten(readings)]


def link_error(sensors: dict) -> str | None:
    """Why the agent got no readings (the robot unplugged, reconnecting), if it did not."""
    return sensors.get("error") if isinstance(sensors.get("error"), str) else None


def show_items(shows: dict) -> list[dict]:
    return [show_item(name, entry) for name, entry in sorted(shows.items())]


def status(sensors: dict, units: dict) -> dict:
    """What the robot's status line says: reachable or not, its battery where it has one."""
    battery = sensors.get("battery")
    if isinstance(battery, bool) or not isinstance(battery, (int, float)):
        battery = None
    return {
        "link_error": link_error(sensors),
        "battery": battery,
        "battery_unit": units.get("battery", ""),
    }
