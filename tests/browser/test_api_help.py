"""Robot API help in the workbench's editor, in a real browser: Ctrl-Space completes the
API's calls with their signatures, pointing at a call or F1 shows its help, and attaching
again switches the language. The workbench does not load api_help.js yet: the tests put it
on the page, by hand and as the two lines its template needs would (WORKBENCH_LINES)."""

import re

import pytest
from django.template import Context, Template
from playwright.sync_api import Page, expect

from tests.browser.test_pages import editor_text, set_editor_text, sign_in

HOVER_DELAY_MS = 350  # api_help.js: how long the pointer rests on a name before its help shows
PYTHON = "import robot\n\nbot = robot.Robot()\n"
LUA = "local Robot = require('robot')\nlocal bot = Robot.new()\n"

# The two lines templates/programs/edit.html needs, after editor.js's.
WORKBENCH_LINES = """\
{% load static %}<link rel="stylesheet" href="{% static 'robotide/api_help.css' %}">
<script src="{% static 'robotide/api_help.js' %}" data-help="{% url 'robot-api-page' %}" \
data-show-hint="{% static 'vendor/codemirror/addon/hint/show-hint.js' %}" defer></script>"""


@pytest.fixture
def bench(new_page, appliance, request) -> Page:
    page = new_page()
    sign_in(page)
    name = f"API help {request.node.name}"[:100]
    response = appliance.api(
        "POST", "/api/programs", {"name": name, "language": "python", "source": PYTHON}
    )
    assert response.status_code == 201, response.text
    page.goto(f"/programs/{response.json()['id']}/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    return page


def load_help(page: Page) -> None:
    page.add_style_tag(url="/static/robotide/api_help.css")
    page.add_script_tag(url="/static/vendor/codemirror/addon/hint/show-hint.js")
    page.add_script_tag(url="/static/robotide/api_help.js")


def attach(page: Page, language: str) -> None:
    page.evaluate(
        "language => robotideApiHelp.attach(window.robotideEditor, language,"
        " `/help/robot-api/${language}.json`)",
        language,
    )


def type_at_end(page: Page, text: str) -> None:
    page.locator(".CodeMirror").click()
    page.keyboard.press("Control+End")
    page.keyboard.type(text)


def help_for(page: Page, language: str) -> None:
    """Wait until the editor has the language's help (the page's policy forbids
    wait_for_function's eval)."""
    page.evaluate(
        """language => new Promise((resolve, reject) => {
          const until = Date.now() + 10000;
          (function check() {
            const state = window.robotideEditor.state.robotideApiHelp;
            if (state && state.language === language && state.help) resolve();
            else if (Date.now() > until) reject(new Error("no help for " + language));
            else setTimeout(check, 50);
          })();
        })""",
        language,
    )


def editor_has_focus(page: Page) -> bool:
    return page.evaluate("window.robotideEditor.hasFocus()")


def test_python_completion_hover_and_keyboard_help(bench, screenshot):
    page = bench
    load_help(page)
    attach(page, "python")
    tip = page.locator("#robotide-api-help-tip")

    type_at_end(page, "bot.dr")
    page.keyboard.press("Control+Space")
    hints = page.locator(".CodeMirror-hints li")
    expect(hints).to_have_count(1)
    expect(hints.first).to_contain_text("bot.drive(linear, angular)")
    expect(hints.first).to_contain_text("Drive at a forward speed and a turn rate")
    expect(tip).to_be_visible()  # the selected call's whole help, beside the list
    expect(tip).to_contain_text("m/s")
    expect(tip).to_contain_text("rad/s")
    # The click into the editor set the hover's timer (350 ms): when it runs, the pointer
    # is on no call, and that must not take the list's tip away.
    page.wait_for_timeout(HOVER_DELAY_MS + 200)
    expect(tip).to_be_visible()
    assert editor_has_focus(page)  # the list does not take the keyboard
    screenshot(page, "api-help")
    page.keyboard.press("Enter")
    expect(page.locator(".CodeMirror-hints")).to_have_count(0)
    page.keyboard.type("0.2, 0.5")
    assert editor_text(page).endswith("bot.drive(0.2, 0.5)")

    # Pointing at the name shows its help; pointing away hides it.
    expect(tip).to_be_hidden()
    page.locator(".CodeMirror-code .cm-property", has_text="drive").hover()
    expect(tip).to_be_visible()
    expect(tip).to_contain_text("bot.drive(linear, angular)")
    expect(tip).to_contain_text("angular")
    expect(tip).to_contain_text("rad/s · turn rate, counter-clockwise (default: 0)")
    expect(tip).to_contain_text("clamped to the robot's limits")
    screenshot(page, "api-help-hover")
    page.locator("h1").hover()
    expect(tip).to_be_hidden()

    # At the start of a line, Ctrl-Space offers whole calls on the program's robot.
    page.keyboard.press("End")
    page.keyboard.press("Enter")
    page.keyboard.type("sen")
    page.keyboard.press("Control+Space")
    expect(hints).to_have_count(2)
    expect(hints.nth(0)).to_contain_text("bot.sensors()")
    expect(hints.nth(1)).to_contain_text("bot.sensor(name)")
    page.keyboard.press("ArrowDown")
    expect(tip).to_contain_text("One reading, by its name.")
    page.keyboard.press("Enter")
    page.keyboard.type("'heading'")
    assert editor_text(page).endswith("bot.sensor('heading')")

    # Ctrl-Space (or F1) on a call's name: its help, by keyboard; Esc closes it, the editor
    # keeps the focus.
    page.keyboard.press("Home")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")  # bot.|sensor
    page.keyboard.press("F1")
    expect(tip).to_be_visible()
    expect(tip).to_contain_text("bot.sensor(name)")
    described = page.evaluate(
        "window.robotideEditor.getInputField().getAttribute('aria-describedby')"
    )
    assert described == "robotide-api-help-tip"
    page.keyboard.press("Escape")
    expect(tip).to_be_hidden()
    assert editor_has_focus(page)
    page.keyboard.press("Control+Space")
    expect(tip).to_contain_text("One reading, by its name.")
    page.keyboard.press("ArrowDown")  # the cursor leaves the name: the help goes
    expect(tip).to_be_hidden()


def test_attaching_again_switches_to_lua(bench, screenshot):
    page = bench
    load_help(page)
    attach(page, "python")
    attach(page, "lua")
    set_editor_text(page, LUA)
    tip = page.locator("#robotide-api-help-tip")
    type_at_end(page, "bot:dr")
    page.keyboard.press("Control+Space")
    hints = page.locator(".CodeMirror-hints li")
    expect(hints).to_have_count(1)
    expect(hints.first).to_contain_text("bot:drive(linear, angular)")
    page.keyboard.press("Enter")
    page.keyboard.type("0.2, 0")
    assert editor_text(page).endswith("bot:drive(0.2, 0)")
    page.keyboard.press("End")
    page.keyboard.press("Enter")
    page.keyboard.type("bot:")
    page.keyboard.press("Control+Space")
    expect(hints.first).to_contain_text("bot:drive(linear, angular)")
    expect(page.locator(".CodeMirror-hints li", has_text="bot.drive")).to_have_count(0)
    page.keyboard.press("Escape")
    expect(page.locator(".CodeMirror-hints")).to_have_count(0)
    page.keyboard.type("say")
    page.keyboard.press("Control+Space")  # say is complete: its help, not a list of one
    expect(page.locator(".CodeMirror-hints")).to_have_count(0)
    expect(tip).to_contain_text("bot:say(text)")
    expect(tip).to_contain_text("Speak a text aloud")
    page.keyboard.press("Escape")
    page.get_by_text("new", exact=True).hover()  # Robot.new(): the connect call's help
    expect(tip).to_be_visible()
    expect(tip).to_contain_text("local bot = Robot.new()")
    expect(tip).to_contain_text("Connect to the robot the program runs on.")
    screenshot(page, "api-help-lua")


def test_shell_and_tcl_name_their_calls_their_own_way(bench):
    page = bench
    load_help(page)
    attach(page, "shell")
    set_editor_text(page, 'echo "heading $(robot sensors heading)"\n')
    tip = page.locator("#robotide-api-help-tip")
    type_at_end(page, "robot memory g")
    page.keyboard.press("Control+Space")
    hints = page.locator(".CodeMirror-hints li")
    expect(hints).to_have_count(1)
    expect(hints.first).to_contain_text("robot memory get KEY")
    page.keyboard.press("Enter")
    page.keyboard.type("laps")
    assert editor_text(page).endswith("robot memory get laps")
    page.locator(".CodeMirror-line", has_text="echo").get_by_text("sensors").hover()
    expect(tip).to_contain_text("robot sensors NAME")  # one reading: a NAME follows
    expect(tip).to_contain_text("prints a number or a text plain")

    attach(page, "tcl")
    set_editor_text(page, "package require robot\n")
    type_at_end(page, "robot::dr")
    page.keyboard.press("Control+Space")
    expect(hints.first).to_contain_text("robot::drive linear ?angular?")
    page.keyboard.press("Enter")
    page.keyboard.type("0.2")
    assert editor_text(page).endswith("robot::drive 0.2")


def test_the_workbench_template_lines_attach_it_and_follow_the_language(bench):
    page = bench
    program_url = page.url
    lines = Template(WORKBENCH_LINES).render(Context())

    def with_the_lines(route):
        response = route.fetch()
        body, found = re.subn(
            r'(<script src="[^"]*robotide/editor\.js"[^>]*></script>)',
            lambda m: m.group(1) + "\n" + lines,
            response.text(),
        )
        assert found == 1
        route.fulfill(response=response, body=body)

    page.route(program_url, with_the_lines)
    page.goto(program_url)
    help_for(page, "python")
    type_at_end(page, "bot.st")
    page.keyboard.press("Control+Space")
    expect(page.locator(".CodeMirror-hints li").first).to_contain_text("bot.stop()")
    page.keyboard.press("Escape")
    page.select_option("#editor-form select[name=language]", "perl")
    help_for(page, "perl")
    set_editor_text(page, "use Robot;\nmy $bot = Robot->new;\n")
    type_at_end(page, "$bot->st")
    page.keyboard.press("Control+Space")
    expect(page.locator(".CodeMirror-hints li").first).to_contain_text("$bot->stop")
    page.keyboard.press("Enter")
    assert editor_text(page).endswith("$bot->stop")


def test_the_help_page_shows_every_language(page_for_help, screenshot):
    page = page_for_help
    page.goto("/help/robot-api/")
    drive = page.locator("section#drive")
    expect(drive.locator("table.forms tbody tr")).to_have_count(7)
    expect(drive).to_contain_text("$bot->drive($linear, $angular)")
    expect(drive).to_contain_text("robot drive LINEAR [ANGULAR]")
    expect(drive.locator("table.params")).to_contain_text("rad/s")
    screenshot(page, "robot-api-page")


@pytest.fixture
def page_for_help(new_page) -> Page:
    page = new_page()
    sign_in(page)
    return page
