"""The debugger's costs (issue 32): what running under it costs a program that hits no
breakpoint, and how soon the workbench shows a breakpoint's pause.

(a) Overhead. A Python program calls ``bot.sensors()`` 10,000 times in a tight loop on the sim
robot and times the loop itself: ``time.perf_counter``, and the program's CPU in it,
``time.process_time`` (what the debugger adds, steadier than the wall clock on a loaded
machine), printed and read back from the run's log. Run plainly (the workbench's Run), under
the debugger with no breakpoint, with a breakpoint on a line never reached, and with a
breakpoint inside the loop whose condition is never true. Every run is started as the
workbench starts it (POST /programs/ID/start, with ``action=debug`` and its ``debug`` spec
for the debugged ones), its console's websocket open before the request; a pause that comes
anyway (none should) is answered with Continue and counted. ROUNDS rounds, the four in turn
in each; each figure is the median round and its ratio to the plain run's median.

(b) Breakpoint hit -> the page shows the paused line. Debian's Chromium (Playwright,
headless) on the program's workbench: a breakpoint set by clicking the editor's gutter, Debug
pressed; the program prints ``time.time()`` just before the breakpoint's line on each of
HITS passes of its loop; the page notes ``Date.now()`` when the paused line's highlight
appears (a MutationObserver installed before Debug), and Continue is clicked after each.
The difference, per hit: p50, p95, max; split at the pause's message reaching the page (its
websocket's message, noted in a capturing listener before the page's own). Both clocks are
the machine's (CLOCK_REALTIME; the sim runs at 1x, so the run's clock is not scaled).

    .venv/bin/python -m benchmarks.debugger [--rounds 7] [--hits 20] [--no-browser]

Figures, never a verdict: no test passes or fails on them.
"""

import argparse
import json
import re
import threading

from benchmarks.common import (
    Figure,
    appliance,
    browser_session,
    median,
    percentile,
    print_table,
    say,
    ws_connect,
)
from tests.appliance import cookie_header

BENCH = "debugger"
ROUNDS = 7
HITS = 20
CALLS = 10_000
RUN_TIMEOUT = 120.0  # s: a deadline for a run to end, not how long one takes

LOOP = f"""\
import time

import robot

bot = robot.Robot()
for i in range(200):  # warm-up: the connection, the sim's first readings
    bot.sensors()
N = {CALLS}
t0, c0 = time.perf_counter(), time.process_time()
for i in range(N):
    reading = bot.sensors()  # IN THE LOOP
elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
print(f"loop {{N}} {{elapsed:.6f}} {{cpu:.6f}}")
if N < 0:
    print("never")  # NEVER REACHED
"""

HIT = """\
import time

import robot

bot = robot.Robot()
for i in range(1000):  # Stop ends it after the hits measured
    bot.sensors()
    print(f"hit {i} {time.time():.6f}")
    here = i  # THE BREAKPOINT
print("done")
"""


def line_of(source: str, marker: str) -> int:
    return next(n for n, text in enumerate(source.splitlines(), 1) if marker in text)


# The four ways (a) runs the loop: None is a plain run, else the debug spec it starts with.
VARIANTS = {
    "plain run": None,
    "debugger, no breakpoint": {"breakpoints": [], "watches": []},
    "debugger, breakpoint never reached": {
        "breakpoints": [{"line": line_of(LOOP, "NEVER REACHED"), "condition": None}],
        "watches": [],
    },
    "debugger, condition never true in the loop": {
        "breakpoints": [{"line": line_of(LOOP, "IN THE LOOP"), "condition": "i < 0"}],
        "watches": [],
    },
}


# -- (a) overhead ------------------------------------------------------------------------------


class Continuer(threading.Thread):
    """Follows the program's workbench console (its websocket, open before the start, as the
    page's is) and answers every pause with Continue: a debugged run that pauses anyway (at
    its entry, say) goes on, and is counted."""

    def __init__(self, app, web, program_id: int):
        super().__init__(daemon=True)
        self.app, self.web, self.program_id = app, web, program_id
        self.ws = ws_connect(app, f"/ws/programs/{program_id}/console/", cookie_header(web))
        self.run_id: int | None = None
        self.pauses = 0
        self.events: dict[str, int] = {}

    def run(self) -> None:
        try:
            for message in self.ws:
                if isinstance(message, str) and message.startswith('{"debug"'):
                    state = json.loads(message)["debug"].get("state")
                    self.events[state] = self.events.get(state, 0) + 1
                    if state == "paused":
                        self.pauses += 1
                        self.command(self.run_id, "continue")
        except Exception:  # closed at the end
            pass

    def command(self, run_id: int, command: str) -> None:
        response = self.web.post(f"/runs/{run_id}/debug", json={"command": command})
        if response.status_code != 202:
            say(f"[{BENCH}] {command} -> {response.status_code} {response.text[:200]}")

    def close(self) -> None:
        self.ws.close()


def start(web, program_id: int, source: str, spec: dict | None) -> int:
    """A run started as the workbench starts one (Run, or Debug with its spec): its id."""
    form = {"source": source, "language": "python", "robot": "sim"}
    if spec is not None:
        form.update(action="debug", debug=json.dumps(spec))
    response = web.post(f"/programs/{program_id}/start", data=form)
    if response.status_code != 200 or "X-Run" not in response.headers:
        raise RuntimeError(f"start refused: {response.status_code} {response.text[:300]}")
    return int(response.headers["X-Run"])


def loop_seconds(app, run_id: int) -> tuple[float, float]:
    """The loop's seconds, and the program's CPU seconds in it, as it printed them."""
    run = app.wait_run(run_id, timeout=RUN_TIMEOUT)
    log = app.api("GET", f"/api/runs/{run_id}/log").text
    found = re.search(r"loop \d+ ([0-9.]+) ([0-9.]+)", log)
    if run["state"] != "finished" or not found:
        raise RuntimeError(f"run {run_id} {run['state']} ({run.get('reason')}): {log[-600:]}")
    return float(found.group(1)), float(found.group(2))


def overhead(app, rounds: int) -> list[Figure]:
    web = browser_session(app)
    program_id = app.create_program("Bench debugger loop", LOOP)["id"]
    follower = Continuer(app, web, program_id)
    follower.start()
    timed: dict[str, list[tuple[float, float]]] = {name: [] for name in VARIANTS}
    try:
        for i in range(rounds):
            for name, spec in VARIANTS.items():
                follower.run_id = run_id = start(web, program_id, LOOP, spec)
                timed[name].append(loop_seconds(app, run_id))
            done = [f"{name} {t[-1][0]:.3f} s (CPU {t[-1][1]:.3f})" for name, t in timed.items()]
            say(f"[{BENCH}] round {i + 1}: {', '.join(done)}")
    finally:
        follower.close()
        web.close()
    figures = []
    for k, what in ((0, "loop"), (1, "program's CPU in the loop")):
        plain = median([t[k] for t in timed["plain run"]])
        for name, values in timed.items():
            found = [t[k] for t in values]
            label = f"{CALLS:,} sensors(), {what}: {name}"
            spread = f"{rounds} rounds: {min(found):.3f}-{max(found):.3f} s"
            figures.append(Figure(BENCH, f"{label}, median", median(found), "s", note=spread))
            if name != "plain run":
                figures.append(Figure(BENCH, f"{label} / plain", median(found) / plain, "x"))
    seen = f"debug events seen: {follower.events}"
    figures.append(Figure(BENCH, "pauses answered in (a), none expected", follower.pauses, "",
                          note=seen))  # fmt: skip
    return figures


# -- (b) breakpoint hit -> paused line shown ------------------------------------------------------

# The program's place in the editor (editor.js: a line class on the paused line's wrapper; it
# goes when the program runs on). Each time one appears: Date.now() and its line's number.
PAUSED_LINE = ".CodeMirror-code .debug-line"
WATCH_PAUSES = r"""(selector) => {
  window.__paused = [];
  let shown = null;
  const note = () => {
    const line = document.querySelector(selector);
    if (line && line !== shown) {
      const number = line.querySelector(".CodeMirror-linenumber");
      window.__paused.push([Date.now(), number ? Number(number.textContent) : null]);
    }
    shown = line;
  };
  new MutationObserver(note).observe(document.body,
    {subtree: true, childList: true, attributes: true, attributeFilter: ["class"]});
  // A pause's message on the console's websocket, noted before the page's own listeners
  // (capture, on window): the split between the way there and the page's drawing.
  window.__arrived = [];
  window.addEventListener("htmx:wsBeforeMessage", (event) => {
    const text = event.detail.message;
    if (typeof text === "string" && text.startsWith('{"debug"') &&
        /"state":\s*"paused"/.test(text)) window.__arrived.push(Date.now());
  }, true);
}"""
CONTINUE = '#debug-panel button[data-command="continue"]'
STOP = '#debug-panel button[data-command="stop"]'


def set_breakpoint(page, line: int) -> None:
    """A click on the line's number, in the editor's gutter (editor.js), as a student sets
    one; the marker seen."""
    page.locator(".CodeMirror-linenumber", has_text=re.compile(rf"^{line}$")).click()
    page.wait_for_selector(".CodeMirror .breakpoint")


def paused_line(app, hits: int) -> list[Figure]:
    from playwright.sync_api import sync_playwright

    from benchmarks.workbench import load_to_editable, sign_in
    from tests.browser.conftest import CHROMIUM, CHROMIUM_ARGS

    program_id = app.create_program("Bench debugger hits", HIT)["id"]
    line = line_of(HIT, "THE BREAKPOINT")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        # bypass_csp: the page's CSP forbids the eval behind wait_for_function.
        page = browser.new_context(base_url=app.url, bypass_csp=True).new_page()
        page.on("pageerror", lambda error: say(f"[{BENCH}] page error: {error}"))
        sign_in(page)
        load_to_editable(page, program_id)
        set_breakpoint(page, line)
        page.evaluate(WATCH_PAUSES, PAUSED_LINE)
        page.locator("#bench-debug").click()
        shown = []  # [Date.now(), line] of each pause at the breakpoint
        seen = 0
        while len(shown) < hits:
            page.wait_for_function(f"window.__paused.length > {seen}", timeout=RUN_TIMEOUT * 1000)
            pause = page.evaluate(f"[...window.__paused[{seen}], window.__arrived[{seen}]]")
            seen += 1
            if pause[1] == line:  # not a pause elsewhere (a debugger's entry, say)
                shown.append(pause)
            page.locator(CONTINUE).click()
        run_id = int(page.locator("#console-run").get_attribute("data-run"))
        page.locator(STOP).click()
        browser.close()
    printed = hit_times(app, run_id)
    hit = [(at, arrived, printed[k] * 1000) for k, (at, _, arrived) in enumerate(shown)
           if k < len(printed)]  # fmt: skip
    delays = [at - sent for at, _, sent in hit]
    way = [arrived - sent for _, arrived, sent in hit if arrived is not None]
    drawing = [at - arrived for at, arrived, _ in hit if arrived is not None]
    say(f"[{BENCH}] hit -> paused line shown, ms: {[round(d, 1) for d in delays]}")
    say(f"[{BENCH}] of which hit -> message at the page: {[round(d, 1) for d in way]}")
    return [
        Figure(BENCH, "breakpoint hit -> paused line shown, p50", percentile(delays, 50), "ms"),
        Figure(BENCH, "breakpoint hit -> paused line shown, p95", percentile(delays, 95), "ms"),
        Figure(
            BENCH,
            "breakpoint hit -> paused line shown, max",
            max(delays),
            "ms",
            note=f"{len(delays)} hits, Continue clicked between them; {seen - len(shown)} other"
            " pauses",
        ),
        Figure(BENCH, "of which hit -> its message at the page, p50", percentile(way, 50), "ms"),
        Figure(BENCH, "of which hit -> its message at the page, p95", percentile(way, 95), "ms"),
        Figure(
            BENCH, "of which message -> line shown (the page), p50", percentile(drawing, 50), "ms"
        ),  # fmt: skip
        Figure(
            BENCH, "of which message -> line shown (the page), p95", percentile(drawing, 95), "ms"
        ),  # fmt: skip
    ]


def hit_times(app, run_id: int) -> list[float]:
    """The program's time.time() before each hit, from its run's log."""
    app.wait_run(run_id, timeout=RUN_TIMEOUT)
    log = app.api("GET", f"/api/runs/{run_id}/log").text
    return [float(t) for t in re.findall(r"hit \d+ ([0-9.]+)", log)]


def run(rounds: int = ROUNDS, hits: int = HITS, browser: bool = True) -> list[Figure]:
    with appliance(BENCH) as app:
        figures = overhead(app, rounds)
        print_table(figures, f"{BENCH} (a)")  # kept if (b) cannot run
        if browser:
            try:
                figures += paused_line(app, hits)
            except Exception as exc:
                figures.append(Figure(BENCH, "(b) could not run", None, "", note=repr(exc)[:300]))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.debugger")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help="rounds of (a)")
    parser.add_argument("--hits", type=int, default=HITS, help="breakpoint hits of (b)")
    parser.add_argument("--no-browser", action="store_true", help="(a) only")
    args = parser.parse_args()
    print_table(run(args.rounds, args.hits, not args.no_browser), BENCH)


if __name__ == "__main__":
    main()
