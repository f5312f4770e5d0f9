"""A start as a user's browser sees it: Debian's chromium, signed in, makes the request in the
page (``fetch`` POST /api/programs/{id}/run with its session and the page's CSRF token, as the
page's own scripts send it), then opens the websocket the answer names (``live``, with the
session's pass) at once and waits for the first output line, timed with ``performance.now()``
(start_overhead's "websocket after", with the browser as the client instead of httpx and
websockets).

Baselines in the same page and run: a GET /healthz round trip and a websocket opened on an
ended run until its first message (the log tail): what the browser and the web tier cost
before any program runs.

    .venv/bin/python -m benchmarks.browser_start
"""

from playwright.sync_api import sync_playwright

from benchmarks.common import Figure, appliance, median, percentile, print_table, say
from benchmarks.workbench import sign_in
from tests.browser.conftest import CHROMIUM, CHROMIUM_ARGS

BENCH = "browser start"
ROUNDS, WARMUP = 20, 2
SOURCES = {"python": "import time; print(time.time())\n", "shell": "echo $EPOCHREALTIME\n"}

# -> [response, websocket open, first line, run] in ms after the request; `run` null: a new
# run, else a websocket (without a pass) on that one.
START = """async ([id, run]) => {
  const csrf = JSON.parse(document.body.getAttribute("hx-headers"))["X-CSRFToken"];
  const t0 = performance.now();
  let live = `/ws/runs/${run}/`;
  if (run === null) {
    const r = await fetch(`/api/programs/${id}/run`, {method: "POST",
      headers: {"X-CSRFToken": csrf, "Content-Type": "application/json"},
      body: JSON.stringify({robot: "sim"})});
    ({id: run, live} = await r.json());
  }
  const t1 = performance.now();
  return await new Promise((done, failed) => {
    const ws = new WebSocket(`ws://${location.host}${live}`);
    let opened;
    ws.onopen = () => { opened = performance.now(); };
    ws.onmessage = (e) => {
      if (e.data.includes('class="ln o"')) {
        const t3 = performance.now();
        ws.close();
        done([t1 - t0, opened - t0, t3 - t0, run]);
      }
    };
    ws.onerror = () => failed("websocket error");
    setTimeout(() => failed("no line in 10 s"), 10000);
  });
}"""
HEALTHZ = """async () => {
  const t0 = performance.now();
  await (await fetch("/healthz")).text();
  return performance.now() - t0;
}"""


def run() -> list[Figure]:
    with appliance(BENCH) as app, sync_playwright() as p:
        programs = {
            name: app.create_program(f"bench browser {name}", source, language=name)["id"]
            for name, source in SOURCES.items()
        }
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        page = browser.new_context(base_url=app.url, bypass_csp=True).new_page()
        sign_in(page)
        page.goto("/programs/")
        rows = {name: [] for name in SOURCES}
        healthz, ended_open = [], []
        ended = None
        for i in range(WARMUP + ROUNDS):
            for name, program in programs.items():
                row = page.evaluate(START, [program, None])
                page.wait_for_timeout(200)  # the run ends, its robot's next box is made
                if i >= WARMUP:
                    rows[name].append(row)
                ended = row[3]
            if i >= WARMUP:
                healthz.append(page.evaluate(HEALTHZ))
                ended_open.append(page.evaluate(START, [None, ended])[2])
        browser.close()
    say(f"[{BENCH}] {rows}")
    figures = []
    for name, found in rows.items():
        for k, what in ((2, "request -> first line"), (0, "request -> response"),
                        (1, "request -> websocket open")):  # fmt: skip
            values = [r[k] for r in found]
            figures += [
                Figure(BENCH, f"{name}: {what}, median", median(values), "ms"),
                Figure(BENCH, f"{name}: {what}, p90", percentile(values, 90), "ms"),
            ]
    figures += [
        Figure(BENCH, "baseline: GET /healthz round trip, median", median(healthz), "ms"),
        Figure(
            BENCH,
            "baseline: websocket on an ended run -> first message, median",
            median(ended_open),
            "ms",
        ),  # fmt: skip
    ]
    return figures


if __name__ == "__main__":
    print_table(run(), BENCH)
