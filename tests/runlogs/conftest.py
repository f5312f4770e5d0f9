# A real agent in this process, as the end-to-end tests have it.
from tests.e2e.conftest import robot_on  # noqa: F401
