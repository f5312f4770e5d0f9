import shutil
import tempfile
from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def fleet_data():
    """FLEET_DATA for a test module: a folder the accounts that robotide.fleet runs its
    PostgreSQL and Redis as (when the tests run as root) can reach, unlike pytest's tmp_path
    under a 0700 folder of root's."""
    folder = Path(tempfile.mkdtemp(prefix="robotide-fleet-"))
    folder.chmod(0o711)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)
