"""The e-stop race (test_estop_race.py) again on PostgreSQL, where presses and resumes of one
robot take turns by a lock on its row (select_for_update), not SQLite's write lock: the same
tests in a pytest of their own whose DATABASE_URL is a PostgreSQL database."""

import os
import subprocess
import sys
import uuid

from tests.appliance import POSTGRES, ROOT, _drop

RACE = "tests/robots/test_estop_race.py"


def test_the_e_stop_race_holds_on_postgresql():
    database = f"robotide_race_{uuid.uuid4().hex[:10]}"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "REDIS_URL"))}
    env["DATABASE_URL"] = f"{POSTGRES}/{database}"
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist"]
    try:
        result = subprocess.run(
            [*command, "--create-db", RACE], env=env, cwd=ROOT, capture_output=True,
            text=True, timeout=600,
        )  # fmt: skip
    finally:
        _drop(f"test_{database}")  # pytest-django's, left when a thread's session outlived it
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert " passed" in result.stdout and " failed" not in result.stdout
