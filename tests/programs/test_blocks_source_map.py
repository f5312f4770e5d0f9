"""Blocks: the Python's source map (the block each line is made for), a run's error traced back
to its block, loose blocks not run, and the generated Python's header in the user's language."""

import json

import pytest
from django.test import Client
from django.urls import reverse
from django.utils import translation

from programs import blocks_worker
from programs.blocks import to_python, to_python_mapped
from programs.runlog import places_for
from tests.programs.test_blocks import (
    EXAMPLES,
    TOKEN,
    arithmetic,
    block,
    num,
    run,
    run_ok,
    show,
    stack,
    text,
)
from tests.robot_api_server import admit


@pytest.fixture
async def agent(agent):
    """The sim robot's agent, as tests/programs/test_blocks.py runs blocks on it."""
    admit(agent, TOKEN, 7)
    return agent


def lines_of(python: str, source_map: list) -> dict[str, list[str]]:
    """Each block id's lines of the Python."""
    found: dict[str, list[str]] = {}
    for line, block_id in zip(python.splitlines(), source_map, strict=False):
        found.setdefault(block_id, []).append(line)
    return found


def test_each_line_of_the_python_names_the_block_it_was_made_for():
    python, source_map = to_python_mapped((EXAMPLES / "square.json").read_text())
    assert len(source_map) == len(python.splitlines())  # one for each line
    lines = lines_of(python, source_map)
    assert lines["square-repeat"] == ["for count in range(4):"]
    forward = ["    bot.drive(0.3, 0.0)", "    time.sleep(1)", "    bot.stop()"]
    assert lines["square-forward"] == forward
    assert lines["square-turn"] == ["    turn(90)"]  # inside the repeat: its own block's
    assert lines["square-print"] == ["print('A square, and back near the start')"]
    # The header, the imports and the turn() helper are no block's.
    assert "def turn(degrees):" in lines[None] and python.splitlines()[0] in lines[None]


def test_the_worker_sends_the_same_map():
    source = (EXAMPLES / "square.json").read_text()
    assert blocks_worker.to_python_mapped(source) == to_python_mapped(source)


def dividing_by_zero() -> tuple[str, str]:
    """A program whose second block divides by zero; and that block's id."""
    divide = show(arithmetic("DIVIDE", num(1), num(0)))
    top = {**stack(show(text("before")), divide, show(text("never"))), "x": 20, "y": 20}
    return json.dumps({"blocks": {"languageVersion": 0, "blocks": [top]}}), divide["id"]


async def test_a_runs_error_leads_back_to_the_block_that_stopped_it(agent, tmp_path):
    """Run as the agent runs it (the Python written as program.py): the error line the
    server marks in the console (places_for) is the Python's, and the map gives the block."""
    source, divide = dividing_by_zero()
    result = await run(agent, tmp_path, source)
    assert result.status == 1 and result.lines == ["before"], result.err
    assert result.err.rstrip().endswith("ZeroDivisionError: division by zero")
    place_of = places_for("blocks", "program")  # the program's name: program.json
    lines = [line for text in result.err.splitlines() if (line := place_of(text))]
    assert lines, result.err
    _, source_map = blocks_worker.to_python_mapped(source)
    assert source_map[lines[-1] - 1] == divide


def test_the_workbench_pane_sends_the_map_with_the_python(admin_user):
    from programs.models import Program

    program = Program.objects.create(owner=admin_user, name="Mapped", language="blocks")
    client = Client()
    client.force_login(admin_user)
    source, divide = dividing_by_zero()
    answer = client.post(reverse("program-blocks-python", args=[program.pk]), {"source": source})
    assert answer.status_code == 200, answer.content
    python, blocks = answer.json()["python"], answer.json()["blocks"]
    assert lines_of(python, blocks)[divide] == ["print(1 / 0)"]


# -- loose blocks ---------------------------------------------------------------------------------


def loose_workspace(**main_extra) -> tuple[str, dict]:
    """A program (a print at the top) and, lower down, a print block attached to nothing, a
    value alone and a stack of two."""
    main = {**show(text("attached")), "x": 20, "y": 20, **main_extra}
    loose = {**show(text("LOOSE")), "x": 20, "y": 200}
    value = {**num(42), "x": 300, "y": 0}  # higher up, but a value alone is no program
    pair = {**stack(show(text("LOOSE too")), show(text("LOOSE 3"))), "x": 0, "y": 400}
    tops = [pair, loose, value, main]  # as saved: in no particular order
    return json.dumps({"blocks": {"languageVersion": 0, "blocks": tops}}), loose


async def test_loose_blocks_do_not_run(agent, tmp_path):
    source, _ = loose_workspace()
    result = await run_ok(agent, tmp_path, source)
    assert result.lines == ["attached"], result.python
    assert "LOOSE" not in result.python and "42" not in result.python


def test_only_the_editors_own_mark_of_loose_is_decided_here():
    """The editor saves a loose block as disabled for being an orphan (Blockly's reason): the
    program decides from where blocks lie, so a stack saved loose that is now the top runs;
    a block the user disabled stays off."""
    source, _ = loose_workspace(disabledReasons=["ORPHANED_BLOCK"])
    assert to_python(source).endswith("\nprint('attached')\n")
    source, _ = loose_workspace(disabledReasons=["MANUALLY_DISABLED"])
    assert "print(" not in to_python(source)


def test_a_workspace_of_values_alone_is_an_empty_program():
    source = json.dumps({"blocks": {"languageVersion": 0, "blocks": [num(1), text("a")]}})
    assert to_python(source).rstrip().endswith("bot = robot.Robot()")


def test_a_loose_unknown_block_is_not_an_error():
    """As Blockly makes no code of a disabled block, a loose block is not read."""
    main = {**show(text("attached")), "x": 20, "y": 20}
    odd = {**block("robot_fly"), "x": 20, "y": 300}
    source = json.dumps({"blocks": {"languageVersion": 0, "blocks": [odd, main]}})
    assert to_python(source).endswith("print('attached')\n")


# -- the header, in the user's language ---------------------------------------------------------


@pytest.mark.parametrize("maker", [to_python, blocks_worker.to_python])
def test_the_header_is_in_the_users_language(maker):
    source = json.dumps({"blocks": {"languageVersion": 0, "blocks": []}})
    with translation.override("pt-br"):
        header = maker(source).splitlines()[0]
    assert header.startswith("# ") and "robotide" in header
    assert "Generated" not in header and "blocos" in header, header
    with translation.override("en"):
        assert maker(source).startswith("# Generated from a blocks program")
