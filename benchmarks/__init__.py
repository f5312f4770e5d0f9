"""robotide's benchmarks: they print figures, they never decide a test's verdict.

Run them all with ``make bench`` or ``.venv/bin/python -m benchmarks``; one with
``.venv/bin/python -m benchmarks.start_overhead`` (or throughput, api_roundtrips, idle_memory,
box_costs, ...).
Each benchmark starts its own real appliance (``robotide up`` in a subprocess, see
tests/appliance.py) on 127.0.0.1 and measures its baselines in the same run.
"""

BENCHMARKS = (
    "idle_memory",
    "start_overhead",
    "browser_start",
    "api_roundtrips",
    "languages",
    "throughput",
    "box_costs",
    "drivers",
    "robot_page",
    "workbench",
    "camera",
    "gateway",
    "fleet",
    "classroom",
    "sims",
    "sim_view",
    "checks",
    "debugger",
)
