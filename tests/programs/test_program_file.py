"""The file a program runs as: named after the program, never after a Robot API client."""

import pytest

from programs.models import program_filename


@pytest.mark.parametrize(
    ("name", "language", "expected"),
    [
        ("Line follower", "python", "line-follower.py"),
        ("Robot", "python", "robot-program.py"),  # robot.py would be its own `import robot`
        ("robot", "lua", "robot-program.lua"),  # Lua's require looks beside the program too
        ("???", "shell", "program.sh"),
    ],
)
def test_program_file_names(name, language, expected):
    assert program_filename(name, language) == expected
