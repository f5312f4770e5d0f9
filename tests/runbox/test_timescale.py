"""A run's clock at its sim's speed (runbox.timescale): libfaketime in the run box, as root
(bubblewrap) and rootless, its processes sharing one clock."""

import json

import pytest

from runbox import timescale
from tests.runbox.test_box import MODES, box_run, readable_copy  # noqa: F401 (a fixture)

# Real time from the kernel's /proc/uptime, which libfaketime does not touch; the program's
# own clock from time.monotonic(); a child's wall clock against its parent's, before and after.
MEASURE = """
import json, subprocess, sys, time

def real():
    return float(open("/proc/uptime").read().split()[0])

real_0, own_0 = real(), time.monotonic()
time.sleep(1)
own, slept_real = time.monotonic() - own_0, real() - real_0
real_0 = real()
subprocess.run(["sleep", "1"], check=True)
child_slept_real = real() - real_0
before = time.time()
child = subprocess.run([sys.executable, "-c", "import time; print(time.time())"],
                       capture_output=True, text=True, check=True)
after = time.time()
print(json.dumps({"own": own, "real": slept_real, "child_real": child_slept_real,
                  "before": before, "child": float(child.stdout), "after": after}))
"""


def measured(result: dict) -> dict:
    assert result["state"] == "finished", result["log"]
    line = next(line for line in result["log"].splitlines() if '"own"' in line)
    return json.loads(line[line.index("{") :])


@pytest.mark.parametrize("mode", MODES)
def test_a_second_of_the_programs_lasts_a_tenth_at_10x(mode, readable_copy):  # noqa: F811
    assert timescale.library(), "libfaketime (scripts/install-test-deps.sh installs it)"
    found = measured(box_run(mode, readable_copy, MEASURE, speed=10))
    assert found["own"] >= 1.0  # by its own clock it slept its second
    # A tenth of a second of real time (0.3 leaves room for a busy machine; 1x takes 1.0).
    assert found["real"] < 0.3, found
    assert found["child_real"] < 0.3, found  # its child's sleep too
    # One clock for the run: the child's reading falls between its parent's two (a child
    # with a clock of its own would start it from real time now, seconds behind).
    assert found["before"] <= found["child"] <= found["after"], found


@pytest.mark.parametrize("mode", MODES)
def test_at_1x_the_clock_is_the_real_one(mode, readable_copy):  # noqa: F811
    found = measured(box_run(mode, readable_copy, MEASURE, speed=1))
    assert 0.95 <= found["real"] and 0.95 <= found["child_real"], found


def test_the_command_is_wrapped_only_faster_than_real_time(monkeypatch):
    assert timescale.command(["python3", "x.py"], 1) == ["python3", "x.py"]
    wrapped = timescale.command(["python3", "x.py"], 10)
    assert wrapped[0] == "/usr/bin/env" and wrapped[-2:] == ["python3", "x.py"]
    assert "FAKETIME=+0 x10" in wrapped and f"LD_PRELOAD={timescale.library()}" in wrapped
    with pytest.raises(ValueError):
        timescale.command(["python3"], 11)
    assert timescale.speed_of({"kind": "sim", "sim": {"speed": 4}}) == 4
    assert timescale.speed_of({"kind": "pioneer"}) == 1


def test_without_libfaketime_a_faster_sim_refuses_its_runs_saying_what_to_install(monkeypatch):
    monkeypatch.setattr(timescale, "library", lambda: None)
    assert timescale.command(["python3"], 1) == ["python3"]  # 1x needs nothing
    with pytest.raises(timescale.TimescaleUnavailable, match="apt-get install libfaketime"):
        timescale.command(["python3", "x.py"], 10)
