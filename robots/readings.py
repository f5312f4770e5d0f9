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
    return [(name, value, units.get(name, "")) for name, value in flatten(sensors)]


def show_items(shows: dict) -> list[dict]:
    return [show_item(name, entry) for name, entry in sorted(shows.items())]
