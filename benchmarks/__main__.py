"""Run the benchmarks (all, or those named) and print one table of figures and targets.

    .venv/bin/python -m benchmarks [idle_memory start_overhead api_roundtrips languages throughput]
    CLASSROOM_BENCH_QUICK=1 .venv/bin/python -m benchmarks classroom   # its --quick

Figures are printed, never asserted: the exit status is 0 however they compare with their
targets, 1 only if a benchmark could not run at all.
"""

import argparse
import importlib
import os
import platform
import sys
import time
import traceback

from benchmarks import BENCHMARKS
from benchmarks.common import Figure, print_table, say


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "names",
        nargs="*",
        choices=[[], *BENCHMARKS],
        metavar="NAME",
        help=f"benchmarks to run (default: all): {', '.join(BENCHMARKS)}",
    )
    args = parser.parse_args(argv)
    names = args.names or list(BENCHMARKS)
    load = os.getloadavg()
    say(
        f"robotide benchmarks on {platform.node()}: {os.cpu_count()} CPU(s), Python"
        f" {platform.python_version()}, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"
    )
    figures: list[Figure] = []
    failed = 0
    started = time.monotonic()
    for name in names:
        t0 = time.monotonic()
        say(f"== {name}")
        try:
            module = importlib.import_module(f"benchmarks.{name}")
            figures += module.run()
        except Exception as exc:
            failed += 1
            traceback.print_exc()
            figures.append(Figure(name, "could not run", None, "", note=repr(exc)))
        say(f"== {name}: {time.monotonic() - t0:.1f} s")
    load = os.getloadavg()
    print_table(
        figures,
        title=f"robotide benchmarks ({time.monotonic() - started:.0f} s,"
        f" load average now {load[0]:.2f}; other work on the machine skews the figures)",
    )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
