"""Blocks as a beginner's block editor: a run's error marks the block it came from and says why
in plain words; a loose block (attached to nothing) is greyed out and does not run. Real runs
on the appliance's sim robot. Screenshots: test-artifacts/screenshots/blocks-error-*.png."""

import json
import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import sign_in

DIVIDE_ID = "divide-print"


def printed(block_id: str, value: dict) -> dict:
    return {"type": "text_print", "id": block_id, "inputs": {"TEXT": {"block": value}}}


def words(block_id: str, text: str) -> dict:
    return printed(block_id, {"type": "text", "id": f"{block_id}-text", "fields": {"TEXT": text}})


def number(block_id: str, value: int) -> dict:
    return {"type": "math_number", "id": block_id, "fields": {"NUM": value}}


def program(*tops: dict) -> str:
    return json.dumps({"blocks": {"languageVersion": 0, "blocks": list(tops)}})


# A print, then a print of 1 / 0, then a print it never reaches.
DIVIDING = program(
    {
        **words("first", "before the error"),
        "x": 30,
        "y": 30,
        "next": {
            "block": {
                **printed(
                    DIVIDE_ID,
                    {
                        "type": "math_arithmetic",
                        "id": "divide",
                        "fields": {"OP": "DIVIDE"},
                        "inputs": {
                            "A": {
                                "block": {"type": "math_number", "id": "a", "fields": {"NUM": 1}}
                            },
                            "B": {
                                "block": {"type": "math_number", "id": "b", "fields": {"NUM": 0}}
                            },
                        },
                    },
                ),
                "next": {"block": words("never", "never printed")},
            }
        },
    }
)

# The program (one print at the top) and a print block lower down, attached to nothing.
WITH_A_LOOSE_BLOCK = program(
    {**words("loose", "LOOSE BLOCK RAN"), "x": 30, "y": 260},
    {**words("main", "attached block ran"), "x": 30, "y": 30},
)


def blocks_program(appliance, name: str, source: str, token=None) -> int:
    made = appliance.create_program(name, source, language="blocks", token=token)
    return made["id"]


def open_blocks(page: Page, program_id: int) -> None:
    page.goto(f"/programs/{program_id}/")
    expect(page.locator("#blocks-area .blocklySvg")).to_be_visible()
    expect(page.locator("#blocks-python")).to_contain_text("bot = robot.Robot()")
    # The robot's panel, loaded after the page, moves the buttons: clicked once it is in.
    expect(page.locator("#bench-panel #sensors")).to_be_visible()


def svg_of(page: Page, block_id: str):
    return page.locator(f'#blocks-area g.blocklyDraggable[data-id="{block_id}"]')


def run_to_the_end(page: Page, state: str) -> None:
    page.locator("button.run").click()
    status = page.locator("#console #run-status")  # its data-state: in any language
    expect(status).to_have_attribute("data-state", state, timeout=30_000)


@pytest.fixture
def bench(new_page, appliance) -> Page:
    appliance.resume()  # whatever an earlier test pressed
    page = new_page()
    sign_in(page)
    return page


def test_a_runtime_error_marks_its_block_and_says_why_in_plain_words(bench, appliance, screenshot):
    page = bench
    page.set_viewport_size({"width": 1366, "height": 900})
    program_id = blocks_program(appliance, "Blocks dividing by zero", DIVIDING)
    open_blocks(page, program_id)
    run_to_the_end(page, "failed")
    console = page.locator("#console")
    expect(console.locator("#log-lines .ln.o")).to_have_text(["before the error"])
    # The console says it in words, the block is named, and what Python said is kept.
    note = console.locator(".blocks-error")
    expect(note).to_contain_text("This block stopped the program: you divided by zero.")
    expect(note.locator("details")).to_contain_text("ZeroDivisionError: division by zero")
    # The block that divided: outlined in red, with a warning icon saying the same.
    expect(svg_of(page, DIVIDE_ID)).to_have_class(has_class("robotide-error-block"))
    warning = page.evaluate(
        """(id) => {
          const block = window.robotideBlocksEditor.workspace.getBlockById(id);
          const icon = block.getIcon(Blockly.icons.IconType.WARNING);
          return icon ? icon.getText() : null;
        }""",
        DIVIDE_ID,
    )
    warning = " ".join((warning or "").split())  # in short lines
    assert "you divided by zero" in warning and "ZeroDivisionError: division by zero" in warning
    for other in ("first", "never"):  # only that one
        expect(svg_of(page, other)).not_to_have_class(has_class("robotide-error-block"))
    screenshot(page, "blocks-error-1366")
    # A console line naming the Python's line leads to the block.
    page.evaluate(
        "Blockly.common.setSelected(robotideBlocksEditor.workspace.getBlockById('first'))"
    )
    console.locator(".ln[data-line]").last.click()
    page.wait_for_function("(id) => Blockly.common.getSelected()?.id === id", arg=DIVIDE_ID)

    # On a phone: the same, the block in view.
    page.set_viewport_size({"width": 390, "height": 844})
    open_blocks(page, program_id)
    run_to_the_end(page, "failed")
    expect(console.locator(".blocks-error")).to_contain_text("you divided by zero")
    expect(svg_of(page, DIVIDE_ID)).to_have_class(has_class("robotide-error-block"))
    screenshot(page, "blocks-error-390")


def test_in_portuguese_the_words_and_the_blocks_defaults(new_page, appliance, screenshot):
    """A pt-BR account: the error's plain words, the generated header, the toolbox's texts."""
    token = appliance.new_user("blocks-bia", password="bia-pass-1234")
    program_id = blocks_program(appliance, "Dividir por zero", DIVIDING, token=token)
    page = new_page(locale="pt-BR")
    page.set_viewport_size({"width": 1366, "height": 900})
    page.goto("/accounts/login/")
    page.get_by_label("Nome de usuário").fill("blocks-bia")
    page.get_by_label("Senha").fill("bia-pass-1234")
    page.get_by_role("button", name="Entrar").click()
    expect(page.get_by_role("button", name="Sair")).to_be_visible()
    open_blocks(page, program_id)
    expect(page.locator("#blocks-python")).to_contain_text(
        "# Gerado pelo robotide a partir de um programa em blocos"
    )
    defaults = page.evaluate(
        """() => {
          const robot = robotideBlocks.toolbox.contents[0].contents;
          const say = robot.find((entry) => entry.type === "robot_say");
          return [say.inputs.TEXT.shadow.fields.TEXT, Blockly.Blocks.robot_publish.init && true];
        }"""
    )
    assert defaults == ["olá", True]
    run_to_the_end(page, "failed")
    expect(page.locator("#console .blocks-error")).to_contain_text(
        "Este bloco parou o programa: você dividiu por zero."
    )
    expect(page.locator("#console .blocks-error summary")).to_have_text("O que o Python disse")
    screenshot(page, "blocks-error-pt-br-1366")


def has_class(name: str) -> re.Pattern:
    """A class attribute holding `name` among others."""
    return re.compile(rf"(^|\s){re.escape(name)}(\s|$)")


def test_a_loose_block_is_greyed_out_and_does_not_run(bench, appliance, screenshot):
    page = bench
    page.set_viewport_size({"width": 1366, "height": 900})
    open_blocks(page, blocks_program(appliance, "Blocks with a loose one", WITH_A_LOOSE_BLOCK))
    enabled = page.evaluate(
        """() => Object.fromEntries(["main", "loose"].map((id) =>
             [id, window.robotideBlocksEditor.workspace.getBlockById(id).isEnabled()]))"""
    )
    assert enabled == {"main": True, "loose": False}
    expect(svg_of(page, "loose")).to_have_class(has_class("blocklyDisabled"))
    expect(page.locator("#blocks-python")).not_to_contain_text("LOOSE")
    screenshot(page, "blocks-loose-1366")
    run_to_the_end(page, "finished")
    log = page.locator("#console #log-lines")
    expect(log.locator(".ln.o")).to_have_text(["attached block ran"])
    expect(log).not_to_contain_text("LOOSE BLOCK RAN")

    # Attached under the program, it runs; dragged off again, it is loose again.
    page.evaluate(
        """() => {
          const ws = window.robotideBlocksEditor.workspace;
          const main = ws.getBlockById("main"), loose = ws.getBlockById("loose");
          main.nextConnection.connect(loose.previousConnection);
        }"""
    )
    expect(page.locator("#blocks-python")).to_contain_text("print('LOOSE BLOCK RAN')")
    assert page.evaluate("window.robotideBlocksEditor.workspace.getBlockById('loose').isEnabled()")
