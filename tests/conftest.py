import os

import pytest

from tests.appliance import Appliance

# The `agent` fixture: a real Robot API server for tests of the API and its clients.
pytest_plugins = ["tests.robot_api_server"]


@pytest.fixture(autouse=True)
def _test_settings(settings, tmp_path):
    settings.RUNS_DIR = tmp_path / "runs"
    settings.PASSWORD_HASHERS = ["django.contrib.auth.hashers.MD5PasswordHasher"]
    # Any free port: tests run side by side, and never listen beyond loopback.
    settings.GATEWAY_DEFAULTS = {"gcs": "127.0.0.1:0", "programs": "127.0.0.1:0"}


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("appliance")).start()
    yield app
    app.stop()


@pytest.fixture(scope="module", params=["embedded", "split"])
def any_appliance(request, tmp_path_factory):
    """The same end-to-end tests, once per deployment mode."""
    app = Appliance(tmp_path_factory.mktemp(request.param), mode=request.param)
    app.start()
    yield app
    app.stop()


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")
