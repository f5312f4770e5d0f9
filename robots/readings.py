"""A robot's readings and shown values, as its page shows them."""

import base64

from programs.access import runs_for_user


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
    item["ended"] = "ended" in entry  # its run ended: the card goes soon (age_shows)
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


# -- whose shown values a viewer sees, and for how long ------------------------------------------
# A shown value is kept by the robot's agent under its name, with the run that showed it. While
# that run runs, everyone who sees the robot sees the value (it is what the robot does now).
# Once the run ended, the value is marked "ended" and only those who may see that run (its
# owner, their teachers, admins: programs.access.runs_for_user) still see it, until
# settings.SHOWS_KEEP_SECONDS after the end: then the agent forgets it.


def age_shows(shows: dict, running, now: float, keep: float) -> tuple[bool, list[str]]:
    """Mark the values of runs no longer ``running`` as ended at ``now``, and take off those
    ended ``keep`` seconds ago or more. Whether any was marked, and the names taken off."""
    marked, gone = False, []
    for name, entry in list(shows.items()):
        if entry["run"] in running:
            continue
        if "ended" not in entry:  # a new dict: the one published before stays as it was
            shows[name] = entry = {**entry, "ended": now}
            marked = True
        if now - entry["ended"] >= keep:
            del shows[name]
            gone.append(name)
    return marked, gone


def ended_runs(shows: dict) -> set[int]:
    return {entry["run"] for entry in shows.values() if "ended" in entry}


def shows_seen(shows: dict, seen_runs) -> dict:
    """The values a viewer sees: those of running runs, and of the ended runs in
    ``seen_runs`` (the ones they may see)."""
    return {n: e for n, e in shows.items() if "ended" not in e or e["run"] in seen_runs}


def seen_by(user, shows: dict) -> dict:
    """The values ``user`` sees of all that are shown (shows_seen)."""
    return shows_seen(shows, runs_seen(user, ended_runs(shows)))


def runs_seen(user, run_ids) -> set[int]:
    """Those of ``run_ids`` that ``user`` may see (one query; none when there are none)."""
    if not run_ids:
        return set()
    return set(runs_for_user(user).filter(pk__in=run_ids).values_list("pk", flat=True))


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
