"""The old name of the sim's arenas, kept for code that still imports it.

The worlds now live in rhal.simulator (rhal.simulator.world, rhal.simulator.worlds); the two
arenas of before are its built-in worlds ``boxes`` and ``square``.
"""

from rhal.simulator.world import Box, Landmark
from rhal.simulator.world import World as Arena
from rhal.simulator.worlds import load

ARENAS: dict[str, Arena] = {name: load(name) for name in ("boxes", "square")}

__all__ = ["ARENAS", "Arena", "Box", "Landmark"]
