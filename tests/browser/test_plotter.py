"""The workbench plotter in a real browser: what a run prints as `name: value` pairs or columns
of numbers, and the numbers it shows, plotted live (uPlot); Pause, CSV export, a plot only for
numbers. What is recorded and drawn is read from plotter.js's hook, window.robotidePlotter."""

import csv
import io

import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import SCREENSHOTS
from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.browser.test_pages import set_editor_text, sign_in
from tests.browser.test_workbench import new_program, open_bench

PAIRS = """\
import time

for r in (0.5, 1.25, 2.0, 1.5, 0.75):
    print(f"range: {r}")
    time.sleep(0.15)
"""
COLUMNS = """\
import time

for a, b in ((1, 10), (2, 20), (3, 30)):
    print(f"{a}, {b}")
    time.sleep(0.15)
"""
RANGE_AND_HEADING = """\
import time

for r, h in ((1.5, 40), (2.5, 45), (3.5, -10)):
    print(f"range: {r}, heading={h}")
    time.sleep(0.15)
"""
SHOWS = """\
import robot, time

bot = robot.Robot()
for i in range(30):
    bot.show("range", i / 2)
    time.sleep(0.1)
"""
FOREVER = """\
import time

i = 0
while True:
    print(f"range: {i}")
    i += 1
    time.sleep(0.05)
"""
MANY = """\
print("constructor: 1, __proto__: 2, toString=3")
print(", ".join(f"s{i}: {i}" for i in range(25)))
for i in range(100):
    print(f"s0: {i}")
"""
STEPS = """\
import time

for i in range(20):
    print(f"step={i}")
    time.sleep(0.05)
"""
WORDS = """\
print("hello")
print("countdown 3")
print("turned 90 degrees")
"""


@pytest.fixture
def page(new_page) -> Page:
    """A browser signed in as admin, with axe-core on hand at AXE_URL."""
    page = new_page()
    page.route(
        f"**{AXE_URL}", lambda route: route.fulfill(path=AXE, content_type="text/javascript")
    )
    sign_in(page)
    return page


def run(page: Page, appliance, name: str, source: str) -> None:
    program = new_program(appliance, name, source)
    open_bench(page, program)
    page.get_by_role("button", name="Save and run").click()


def finished(page: Page) -> None:
    expect(page.locator("#console #run-status .state")).to_have_text("finished", timeout=30_000)


def plotted(page: Page, expression: str):
    return page.evaluate(f"() => window.robotidePlotter.{expression}")


def wait_for_values(page: Page, series: str, count: int) -> list[float]:
    page.wait_for_function(
        "([name, count]) => window.robotidePlotter.values(name).length >= count",
        arg=[series, count],
    )
    return plotted(page, f"values({series!r})")


def drawn_in(page: Page, color: str) -> int:
    """How many pixels of the chart's canvas are of `color` (#rrggbb): a series' line."""
    return page.evaluate(
        """(color) => {
          const canvas = document.querySelector("#plotter-chart canvas");
          const want = [1, 3, 5].map(i => parseInt(color.slice(i, i + 2), 16));
          const {width, height} = canvas;
          const pixels = canvas.getContext("2d").getImageData(0, 0, width, height).data;
          const near = (i) => want.every((c, k) => Math.abs(pixels[i + k] - c) < 24);
          let count = 0;
          for (let i = 0; i < pixels.length; i += 4) if (pixels[i + 3] > 200 && near(i)) count++;
          return count;
        }""",
        color,
    )


LINES = [
    ("range: 1.2, heading: 40", [["range", 1.2], ["heading", 40]]),
    ("x=1 y=-2.5e3", [["x", 1], ["y", -2500]]),
    ("left speed: 3\tright speed: 4", [["left speed", 3], ["right speed", 4]]),
    ("{'range': 1.5, 'bump': 0}", [["range", 1.5], ["bump", 0]]),
    ('{"range": 2}', [["range", 2]]),
    ("distância: 0.5.", [["distância", 0.5]]),
    ("1 2\t3", [["value 1", 1], ["value 2", 2], ["value 3", 3]]),
    ("1.5, nan", [["value 1", 1.5], ["value 2", None]]),
    ("countdown 3", []),
    ("t=0.5s", []),
    ("hello", []),
    ("", []),
]


def test_lines_read_as_arduino_reads_them(page, appliance):
    open_bench(page, new_program(appliance, "Plot parse", "print(1)\n"))
    lines = [line for line, _pairs in LINES]
    read = page.evaluate("(lines) => lines.map(window.robotidePlotter.parse)", lines)
    assert dict(zip(lines, read, strict=True)) == dict(LINES)


def test_printed_pairs_are_plotted(page, appliance, screenshot):
    plotter = page.locator("#plotter")
    run(page, appliance, "Plot pairs", PAIRS)
    expect(plotter).to_be_visible()
    expect(plotter.get_by_role("heading", name="Plotter")).to_be_visible()
    assert wait_for_values(page, "range", 5) == [0.5, 1.25, 2.0, 1.5, 0.75]
    finished(page)
    assert plotted(page, "series()") == ["range"]
    chart = plotter.get_by_role("img", name="Chart of the numbers the run printed and showed")
    expect(chart).to_be_visible()
    page.wait_for_function("() => window.robotidePlotter.view().drawn === 5")
    assert drawn_in(page, plotted(page, "colors[0]")) > 20  # the line is on the canvas
    expect(plotter.locator("#plotter-summary")).to_contain_text("range 0.75")
    expect(plotter.locator(".u-legend")).to_contain_text("range")
    plotter.scroll_into_view_if_needed()
    screenshot(page, "plotter-1280")
    plotter.screenshot(path=SCREENSHOTS / "plotter-1280-section.png")
    assert not axe_violations(page)
    page.set_viewport_size({"width": 390, "height": 844})
    page.wait_for_function(
        "() => document.querySelector('#plotter-chart canvas').getBoundingClientRect().right <= 390"
    )
    box = plotter.bounding_box()
    assert box["x"] >= 0 and box["x"] + box["width"] <= 390
    plotter.scroll_into_view_if_needed()
    screenshot(page, "plotter-390")
    plotter.screenshot(path=SCREENSHOTS / "plotter-390-section.png")


def test_two_columns_are_two_series(page, appliance):
    run(page, appliance, "Plot columns", COLUMNS)
    assert wait_for_values(page, "value 2", 3) == [10, 20, 30]
    assert plotted(page, "values('value 1')") == [1, 2, 3]
    assert plotted(page, "series()") == ["value 1", "value 2"]
    finished(page)


def test_a_shown_number_is_a_series(page, appliance, screenshot):
    run(page, appliance, "Plot shows", SHOWS)
    values = wait_for_values(page, "show: range", 3)
    assert set(values) <= {i / 2 for i in range(30)}
    assert len(set(values)) >= 2  # it changed while sampled
    expect(page.locator("#plotter")).to_be_visible()
    finished(page)
    page.locator("#plotter").screenshot(path=SCREENSHOTS / "plotter-shows-section.png")


def test_export_csv_holds_the_values(page, appliance):
    run(page, appliance, "Plot CSV", RANGE_AND_HEADING)
    wait_for_values(page, "heading", 3)
    finished(page)
    with page.expect_download() as download:
        page.get_by_role("button", name="Export CSV").click()
    assert download.value.suggested_filename.startswith("plot-csv-run-")
    assert download.value.suggested_filename.endswith("-plot.csv")
    rows = list(csv.reader(io.StringIO(open(download.value.path(), encoding="utf-8").read())))
    assert rows[0] == ["time_s", "range", "heading"]
    assert [row[1:] for row in rows[1:]] == [["1.5", "40"], ["2.5", "45"], ["3.5", "-10"]]
    times = [float(row[0]) for row in rows[1:]]
    assert times == sorted(times) and times[0] >= 0


def test_pause_freezes_the_view_while_values_are_recorded(page, appliance):
    run(page, appliance, "Plot pause", FOREVER)
    wait_for_values(page, "range", 3)
    pause = page.get_by_role("button", name="Pause")
    pause.click()
    resume = page.get_by_role("button", name="Resume")
    expect(resume).to_have_attribute("aria-pressed", "true")
    view = plotted(page, "view()")
    points = plotted(page, "points()")
    page.wait_for_function("(n) => window.robotidePlotter.points() >= n + 5", arg=points)
    assert plotted(page, "view()") == view  # recorded, not drawn
    assert not plotted(page, "following()")
    resume.click()
    expect(pause).to_have_attribute("aria-pressed", "false")
    page.wait_for_function("(max) => window.robotidePlotter.view().max > max", arg=view["max"])
    page.locator("#bench-stop").click()
    expect(page.locator("#console #run-status .state")).to_have_text("stopped")


def test_words_make_no_plot(page, appliance):
    run(page, appliance, "Plot words", WORDS)
    finished(page)
    expect(page.locator("#console #log-lines .ln.o")).to_have_count(3)
    expect(page.locator("#plotter")).to_be_hidden()
    assert plotted(page, "points()") == 0


def test_series_and_points_are_capped_and_the_page_says_so(page, appliance):
    program = new_program(appliance, "Plot caps", MANY)
    open_bench(page, program)
    # Fewer points kept than the program prints: the limit is the page's, lowered here.
    page.locator("#plotter").evaluate("(plotter) => { plotter.dataset.maxPoints = 50; }")
    page.get_by_role("button", name="Save and run").click()
    finished(page)
    page.wait_for_function("() => window.robotidePlotter.values('s0').at(-1) === 99")
    names = ["constructor", "__proto__", "toString"] + [f"s{i}" for i in range(17)]
    assert plotted(page, "series()") == names
    expect(page.locator("#plotter-too-many")).to_be_visible()
    expect(page.locator("#plotter-dropped")).to_be_visible()
    assert 50 <= plotted(page, "points()") <= 55
    assert plotted(page, "values('s0')")[0] > 0  # the oldest went


def test_history_and_zoom_go_back_and_resume_follows(page, appliance):
    run(page, appliance, "Plot history", STEPS)
    finished(page)
    wait_for_values(page, "step", 20)
    page.wait_for_function("() => window.robotidePlotter.view().drawn === 20")
    live = plotted(page, "view()")
    history = page.get_by_label("History")
    history.fill("0")  # the slider's start: the run's first values
    back = plotted(page, "view()")
    assert back["max"] < live["max"] and not plotted(page, "following()")
    expect(page.locator("#plotter-view")).to_contain_text("Showing")
    resume = page.get_by_role("button", name="Resume")
    resume.click()
    page.wait_for_function("(max) => window.robotidePlotter.view().max === max", arg=live["max"])
    # Dragging across the chart zooms into that stretch and stops following.
    over = page.locator("#plotter-chart .u-over").bounding_box()
    y = over["y"] + over["height"] / 2
    page.mouse.move(over["x"] + over["width"] * 0.2, y)
    page.mouse.down()
    page.mouse.move(over["x"] + over["width"] * 0.5, y, steps=5)
    page.mouse.up()
    zoomed = plotted(page, "view()")
    assert live["min"] < zoomed["min"] < zoomed["max"] < live["max"]
    expect(resume).to_have_attribute("aria-pressed", "true")
    resume.click()
    page.wait_for_function("(max) => window.robotidePlotter.view().max === max", arg=live["max"])


def test_a_new_run_starts_a_new_plot(page, appliance):
    run(page, appliance, "Plot again", PAIRS)
    wait_for_values(page, "range", 5)
    finished(page)
    first = plotted(page, "run()")
    set_editor_text(page, COLUMNS)
    page.get_by_role("button", name="Save and run").click()
    page.wait_for_function("(first) => window.robotidePlotter.run() !== first", arg=first)
    assert wait_for_values(page, "value 1", 3) == [1, 2, 3]
    assert plotted(page, "series()") == ["value 1", "value 2"]  # range is gone
    finished(page)
    second = plotted(page, "run()")
    set_editor_text(page, WORDS)
    page.get_by_role("button", name="Save and run").click()
    page.wait_for_function("(second) => window.robotidePlotter.run() !== second", arg=second)
    finished(page)
    expect(page.locator("#console #log-lines .ln.o")).to_have_text(
        ["hello", "countdown 3", "turned 90 degrees"]
    )
    expect(page.locator("#plotter")).to_be_hidden()
    assert plotted(page, "points()") == 0
