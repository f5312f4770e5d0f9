"""Every language on the same Robot API: the same example on the sim robot, and clear errors.

Real runs through the appliance: each program is started by its agent in its own account and
sandbox, with only its language's client on its interpreter's path.
"""

import re
from pathlib import Path

import pytest

from programs.languages import LANGUAGES
from tests.appliance import Appliance, wait_for

EXAMPLES = Path(__file__).resolve().parents[2] / "programs" / "examples"

# A program that calls a method the API lacks, then asks for a sensor the sim robot lacks.
ERRORS = {
    "python": "import robot\nrobot.Robot().sensor('gps')\n",
    "shell": "robot sensors gps\n",
    "perl": "use Robot;\nRobot->new->sensor('gps');\n",
    "ruby": "require 'robot'\nRobot.new.sensor('gps')\n",
    "lua": "local Robot = require('robot')\nRobot.new():sensor('gps')\n",
    "javascript": "const { Robot } = require('robot');\n"
    "(async () => { const bot = new Robot(); await bot.sensor('gps'); })();\n",
    "tcl": "package require robot\nrobot::sensor gps\n",
    # (printed: a value block alone is loose, not run)
    "blocks": '{"blocks": {"blocks": [{"type": "text_print", "inputs": {"TEXT": {"block": '
    '{"type": "robot_sensor", "fields": {"SENSOR": "gps"}}}}}]}}',
}
UNKNOWN_METHOD = {
    "python": "import robot\nrobot.Robot().call('fly', 1)\n",
    "shell": "robot fly\n",
    "perl": "use Robot;\nRobot->new->call('fly', 1);\n",
    "ruby": "require 'robot'\nRobot.new.call('fly', 1)\n",
    "lua": "local Robot = require('robot')\nRobot.new():call('fly', 1)\n",
    "javascript": "const { Robot } = require('robot');\n"
    "(async () => { const bot = new Robot(); await bot.call('fly', 1); })();\n",
    "tcl": "package require robot\nrobot::call fly 1\n",
    # Blocks refuse a block they do not know before anything is called.
    "blocks": '{"blocks": {"blocks": [{"type": "robot_fly"}]}}',
}


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("languages")).start()
    yield app
    app.stop()


def test_every_language_is_available(app):
    expected = {"python", "blocks", "shell", "perl", "ruby", "lua", "javascript", "tcl"}
    assert set(LANGUAGES) == expected
    missing = [lang.name for lang in LANGUAGES.values() if not lang.available]
    assert not missing, f"interpreters missing: {missing}"


@pytest.mark.parametrize("language", sorted(LANGUAGES))
def test_the_wall_and_turn_example(app, language):
    robot = f"sim-{language}"
    body = {"name": robot, "url": "sim://?arena=square"}
    assert app.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: app.api("GET", f"/api/robots/{robot}/sensors").status_code == 200)
    source = (EXAMPLES / f"wall_turn{LANGUAGES[language].extension}").read_text()
    program = app.create_program(f"wall turn {language}", source, language=language)
    run = app.wait_run(app.run_program(program["id"], robot=robot)["id"], timeout=60)
    log = app.api("GET", f"/api/runs/{run['id']}/log").text
    assert run["state"] == "finished", log
    printed = float(re.search(r"^heading: (-?\d+(\.\d)?)$", log, re.M).group(1))
    sensors = app.api("GET", f"/api/robots/{robot}/sensors").json()
    assert sensors["velocity"] == {"linear": 0.0, "angular": 0.0}  # moved, then stopped
    assert sensors["odometry"]["distance"] > 1.0 and not sensors["bumper"]
    assert sensors["range"] > 0.5  # turned away from the wall it stopped at
    assert abs((printed - sensors["heading"] + 180) % 360 - 180) < 0.1
    page = app.session().get(f"/robots/{robot}/").text
    shown = re.search(
        r"heading <span class=\"muted\">run #\d+( · ended)?</span></figcaption>\s*"
        r"<output>([^<]+)</output>",
        page,
    )
    assert shown and abs(float(shown.group(2)) - printed) < 0.051


@pytest.mark.parametrize("language", sorted(LANGUAGES))
@pytest.mark.parametrize("case", ["missing sensor", "unknown method"])
def test_an_rpc_error_is_a_clear_error(app, language, case):
    source = (ERRORS if case == "missing sensor" else UNKNOWN_METHOD)[language]
    program = app.create_program(f"error {case} {language}", source, language=language)
    run = app.wait_run(app.run_program(program["id"])["id"])
    stderr = app.api("GET", f"/api/runs/{run['id']}/log?stream=stderr").text
    assert run["state"] == "failed" and run["exit_code"] != 0, stderr
    expected = "gps" if case == "missing sensor" else "fly"
    assert expected in stderr, stderr
