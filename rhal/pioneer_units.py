"""What one Pioneer's units are worth: its model's factors (rhal.pioneer_models), each one
overridable in the robot's settings, and where each came from, for the robot page.

The model is the one the robot names in its SYNC2 reply (its subclass, lower-cased as ARIA
does), unless the settings name one. A robot that names a model ARIA has no file for is read
as an SH controller reads (millimetres), and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from rhal.pioneer_models import MODELS, PioneerModel, SonarDisc, model_for

FALLBACK = "p3dx-sh"  # millimetres and the P3 ring: what MobileSim's default robot is
FRONT_ARC = 20.0  # degrees either side of straight ahead: the discs that give "range"
#: The factors a robot's settings may override: option name -> PioneerModel field.
FACTORS = {
    "dist_conv": "dist_conv",
    "angle_conv": "angle_conv",
    "vel_conv": "vel_conv",
    "range_conv": "range_conv",
}


@dataclass(frozen=True)
class Units:
    model: PioneerModel
    chosen_by: str  # how the model was chosen, in words
    overridden: dict[str, Any] = field(default_factory=dict)  # option -> value set
    mm_per_unit: float = 1.0  # position
    rad_per_unit: float = math.tau / 4096  # heading
    mm_s_per_unit: float = 1.0  # wheel speeds
    mm_per_range_unit: float = 1.0  # sonar
    track: float = 0.357  # m, turning wheel speeds into a turn rate without ROTVEL
    sonars: tuple[SonarDisc, ...] = ()
    front_sonars: tuple[int, ...] = ()
    front_bumpers: int = 0
    rear_bumpers: int = 0

    def describe(self) -> dict[str, Any]:
        """The model in force, for capabilities() and the robot page."""
        model = self.model
        return {
            "name": model.subclass,
            "class": model.robot_class,
            "source": model.source,
            "chosen_by": self.chosen_by,
            "overridden": dict(self.overridden),
            "factors": [
                {
                    "name": name,
                    "value": value,
                    "unit": unit,
                    "shown": f"{value:.6g} {unit}",
                    "source": "settings" if name in self.overridden else "model",
                }
                for name, value, unit in (
                    ("dist_conv", self.mm_per_unit, "mm"),
                    ("angle_conv", self.rad_per_unit, "rad"),
                    ("vel_conv", self.mm_s_per_unit, "mm/s"),
                    ("range_conv", self.mm_per_range_unit, "mm"),
                    ("track", self.track, "m"),
                )
            ],
            "max_velocity": model.max_velocity / 1000.0,  # m/s
            "max_rvelocity": math.radians(model.max_rvelocity),  # rad/s
        }


def fit(subclass: str | None, options: dict[str, Any]) -> Units:
    """The units for a robot that named ``subclass`` (None before it has), given the
    ``model``, factor, ``track``, ``sonars`` and bumper options of its settings (None: unset)."""
    model, chosen_by = _choose(subclass, options.get("model"))
    overridden = {name: value for name, value in options.items() if value is not None}
    overridden.pop("model", None)
    factor = {name: overridden.get(name, getattr(model, attr)) for name, attr in FACTORS.items()}
    sonars = model.sonars
    if (count := overridden.get("sonars")) is not None:
        sonars = (sonars + _unplaced(count - len(sonars)))[:count]
    track = overridden.get("track", 2.0 / model.diff_conv / 1000.0)
    return Units(
        model=model,
        chosen_by=chosen_by,
        overridden=overridden,
        mm_per_unit=factor["dist_conv"],
        # A file's AngleConvFactor is 2*pi/4096 (or /1024) printed to 5 places, so a full turn
        # would read 359.06 degrees: taken exactly, unless the settings give one.
        rad_per_unit=factor["angle_conv"] if "angle_conv" in overridden else _exact_turn(model),
        mm_s_per_unit=factor["vel_conv"],
        mm_per_range_unit=factor["range_conv"],
        track=track,
        sonars=sonars,
        front_sonars=tuple(
            number
            for number, disc in enumerate(sonars)
            if disc.x > 0 and abs(disc.heading) <= FRONT_ARC
        ),
        front_bumpers=overridden.get("front_bumpers", model.front_bumpers),
        rear_bumpers=overridden.get("rear_bumpers", model.rear_bumpers),
    )


def _choose(subclass: str | None, named: str | None) -> tuple[PioneerModel, str]:
    if named:
        model = model_for(named)
        if model is None:
            raise ValueError(f"no ARIA model {named!r}; known: {', '.join(sorted(MODELS))}")
        return model, f"the robot's settings (model = {named})"
    if subclass is None:
        return MODELS[FALLBACK], "not connected yet"
    model = model_for(subclass)
    if model is None:
        return MODELS[FALLBACK], (
            f"the robot names model {subclass!r}, which ARIA has no file for: read in "
            f"millimetres as {FALLBACK}; set model in the robot's settings if it is wrong"
        )
    return model, f"the robot's reply (SYNC2 subclass {subclass!r})"


def _exact_turn(model: PioneerModel) -> float:
    """Controllers count a turn in a power of two (4096; 1024 on a Pioneer 1)."""
    return math.tau / 2 ** round(math.log2(math.tau / model.angle_conv))


def _unplaced(count: int) -> tuple[SonarDisc, ...]:
    """Discs the settings add beyond the model's ring: numbered, position unknown."""
    return tuple(SonarDisc(0.0, 0.0, 180.0) for _ in range(max(0, count)))
