"""The classroom benchmark's people, as asyncio clients in one process: students at their
workbenches, a teacher pressing an e-stop, and one student attacking the machine.

Each records what it timed in a `Record` (wall-clock start, milliseconds, whether it was
answered as asked); benchmarks/classroom.py splits those by phase and prints the figures.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import re
import time
from collections import Counter
from dataclasses import dataclass, field

import httpx
from websockets.asyncio.client import connect

ENDED = ("finished", "failed", "stopped", "lost")
RUN_SHOWN = re.compile(r'data-run="(\d+)"')
STATE_SHOWN = re.compile(r'id="run-status"[^>]*data-state="(\w+)"')
PAGE_TIMEOUT = 60.0  # s: a page that long is counted (as its time), not waited for longer
RUN_TIMEOUT = 90.0  # s a student waits for a run's end before asking the API
ATTACK_TIMEOUT = 300.0  # s an attacker's request may take (a blocks compile took 74 s)


@dataclass
class Record:
    """What the clients timed: (wall-clock start, ms, answer, label) per sample; the answer
    is the HTTP status, or the error's name."""

    pages: list = field(default_factory=list)
    estops: list = field(default_factory=list)
    resumes: list = field(default_factory=list)
    runs: list = field(default_factory=list)  # (asked, ms to its end, state ended, robot)


class Session:
    """A signed-in browser: its cookies, and the CSRF token its scripts send."""

    def __init__(self, url: str, username: str, password: str):
        self.url, self.username, self.password = url, username, password
        self.http = httpx.AsyncClient(base_url=url, timeout=PAGE_TIMEOUT)

    async def sign_in(self) -> None:
        page = await self.http.get("/accounts/login/")
        csrf = re.search(r'name="csrfmiddlewaretoken" value="([^"]+)"', page.text).group(1)
        form = {"username": self.username, "password": self.password, "csrfmiddlewaretoken": csrf}
        answer = await self.http.post("/accounts/login/", data=form, follow_redirects=True)
        if "Sign out" not in answer.text:
            raise RuntimeError(f"{self.username} could not sign in ({answer.status_code})")
        self.http.headers["X-CSRFToken"] = self.http.cookies["csrftoken"]

    def cookie(self) -> str:
        return "; ".join(f"{k}={v}" for k, v in self.http.cookies.items())

    async def close(self) -> None:
        await self.http.aclose()


async def timed_get(session: Session, path: str, label: str, record: Record) -> None:
    started, t = time.time(), time.perf_counter()
    try:
        answer = (await session.http.get(path)).status_code
    except httpx.HTTPError as exc:
        answer = type(exc).__name__
    record.pages.append((started, (time.perf_counter() - t) * 1000, answer, label))


async def why_not_finished(http: httpx.AsyncClient, run_id: int) -> str:
    """Why a run did not finish, as the API says, and its last line on stderr (asked only
    then)."""
    why = ""
    with contextlib.suppress(httpx.HTTPError, ValueError, KeyError):
        why = short((await http.get(f"/api/runs/{run_id}")).json()["reason"], 70)
        log = await http.get(f"/api/runs/{run_id}/log?stream=stderr")
        lines = [line for line in log.text.splitlines() if line.strip()]
        # numbers (a run's, a student's) out, so that like failures are counted together
        why += f"; stderr: {short(re.sub(r'[0-9]+', 'N', lines[-1]), 90)}" if lines else ""
    return f" ({why})" if why else ""


class Student:
    """A workbench open on their program, its console's websocket connected: Run pressed
    (the workbench's save-and-run request), the run followed on the console to its end, then
    a few pages between pauses (the run's page, the program list, the workbench again)."""

    def __init__(self, session: Session, program: int, source: str, robot: str, think: tuple):
        self.session, self.program, self.source, self.robot = session, program, source, robot
        self.think = think
        self.ended: dict[int, str] = {}
        self.waiting: dict[int, asyncio.Future] = {}
        self.last_run: int | None = None

    async def open_console(self, port: int) -> None:
        self.ws = await connect(
            f"ws://127.0.0.1:{port}/ws/programs/{self.program}/console/",
            additional_headers={"Cookie": self.session.cookie(), "Origin": self.session.url},
            max_size=None, compression=None, ping_interval=None, open_timeout=60,
        )  # fmt: skip
        self.reader = asyncio.create_task(self._read_console())

    async def _read_console(self) -> None:
        shown = None
        with contextlib.suppress(Exception):
            async for message in self.ws:
                if match := RUN_SHOWN.search(message):
                    shown = int(match[1])
                match = STATE_SHOWN.search(message)
                if shown is not None and match and match[1] in ENDED:
                    self.ended[shown] = match[1]
                    future = self.waiting.pop(shown, None)
                    if future is not None and not future.done():
                        future.set_result(match[1])

    async def work(self, stop: asyncio.Event, record: Record) -> None:
        await asyncio.sleep(random.uniform(0, self.think[1]))  # the class does not click at once
        while not stop.is_set():
            await self.run_once(record)
            for path, label in self.pages():
                await self.pause(stop)
                await timed_get(self.session, path, label, record)

    def pages(self) -> list[tuple[str, str]]:
        run_page = [(f"/runs/{self.last_run}/", "run page")] if self.last_run else []
        workbench = (f"/programs/{self.program}/", "workbench")
        return [*run_page, ("/programs/", "program list"), workbench]

    async def pause(self, stop: asyncio.Event) -> None:
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), random.uniform(*self.think) / 3)

    async def run_once(self, record: Record) -> None:
        asked, t = time.time(), time.perf_counter()
        form = {"source": self.source, "language": "python", "robot": self.robot}
        try:
            answer = await self.session.http.post(f"/programs/{self.program}/start", data=form)
            if answer.status_code != 200 or "X-Run" not in answer.headers:
                state = f"HTTP {answer.status_code}"
            else:
                self.last_run = int(answer.headers["X-Run"])
                state = await self.wait_ended(self.last_run)
                if state != "finished":
                    state += await why_not_finished(self.session.http, self.last_run)
        except httpx.HTTPError as exc:
            state = type(exc).__name__
        record.runs.append((asked, (time.perf_counter() - t) * 1000, state, self.robot))

    async def wait_ended(self, run_id: int) -> str:
        if run_id in self.ended:
            return self.ended[run_id]
        future = self.waiting[run_id] = asyncio.get_running_loop().create_future()
        try:
            return await asyncio.wait_for(future, RUN_TIMEOUT)
        except TimeoutError:
            self.waiting.pop(run_id, None)
        with contextlib.suppress(httpx.HTTPError, ValueError, KeyError):
            answer = await self.session.http.get(f"/api/runs/{run_id}")
            return "not ended: " + answer.json()["state"]
        return "not ended"

    async def close(self) -> None:
        with contextlib.suppress(Exception):
            await self.ws.close()
        self.reader.cancel()
        await self.session.close()


async def teacher(url: str, token: str, robot: str, stop: asyncio.Event, record: Record) -> None:
    """A teacher (staff) presses the robot's emergency stop, and resumes it 0.4 s after the
    answer, once a second on a fixed schedule whether or not the last press was answered: a
    stall is counted in every press it delays, not once (no coordinated omission)."""
    headers = {"Authorization": f"Bearer {token}"}
    limits = httpx.Limits(max_connections=PRESSES_IN_FLIGHT)
    async with httpx.AsyncClient(
        base_url=url, headers=headers, timeout=PAGE_TIMEOUT, limits=limits
    ) as http:
        presses: set[asyncio.Task] = set()
        while not stop.is_set():
            if len(presses) < PRESSES_IN_FLIGHT:
                task = asyncio.create_task(press_and_resume(http, robot, record))
                presses.add(task)
                task.add_done_callback(presses.discard)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 1.0)
        if presses:
            await asyncio.wait(presses)


PRESSES_IN_FLIGHT = 60  # a minute of presses waiting on a stalled server


async def press_and_resume(http: httpx.AsyncClient, robot: str, record: Record) -> None:
    for action, samples in (("estop", record.estops), ("resume", record.resumes)):
        started, t = time.time(), time.perf_counter()
        try:
            answer = (await http.post(f"/api/robots/{robot}/{action}")).status_code
        except httpx.HTTPError as exc:
            answer = type(exc).__name__
        samples.append((started, (time.perf_counter() - t) * 1000, answer, action))
        if action == "estop":
            await asyncio.sleep(0.4)


# -- the attacker -------------------------------------------------------------------------------


@dataclass
class AttackPlan:
    robot: str  # the robot the attacker's runs ask for
    blocks_json: str  # (1) the workspace that generates megabytes of Python
    hog_source: str  # (2) a Python program holding memory
    hogs: int  # (2) how many at once
    flood_source: str  # (3) a shell program flooding its log
    floods_at_once: int
    floods: int  # (3) in all


class Attacker:
    """One student sending (1) blocks that make megabytes of Python, to the blocks-to-Python
    view and as a run, (2) many runs each holding hundreds of MB, (3) log floods, all at once;
    and noting how the server answered each: `answers[kind]` holds (what was answered, s)."""

    KINDS = ("blocks view", "blocks run", "hog", "flood")

    def __init__(self, session: Session, token: str, view_program: int, plan: AttackPlan):
        self.session, self.plan, self.view_program = session, plan, view_program
        self.api = httpx.AsyncClient(
            base_url=session.url, headers={"Authorization": f"Bearer {token}"},
            timeout=ATTACK_TIMEOUT,
        )  # fmt: skip
        self.answers: dict[str, list[tuple[str, float]]] = {kind: [] for kind in self.KINDS}
        self.launched: Counter = Counter()  # kind -> runs asked
        self.kind_of: dict[int, str] = {}  # run id -> its kind
        self.runs: dict[int, dict] = {}  # run id -> the API's last answer about it
        self.seen: dict[int, list[str]] = {}  # run id -> the states it was seen in, in order
        # kind (or all together) -> most runs of it seen running at one look
        self.most_running: Counter = Counter()
        self.queued_reasons: Counter = Counter()

    async def attack(self, stop: asyncio.Event) -> None:
        plan = self.plan
        watcher = asyncio.create_task(self.watch_runs())
        blocks = await self.create("blocks run", "Big ifs", "blocks", plan.blocks_json)
        flood = await self.create("flood", "Flood", "shell", plan.flood_source)
        hog = await self.create("hog", "Hog", "python", plan.hog_source)
        # Asked in this order (blocks, floods, hogs), so that a queue of the attacker's runs
        # serves each kind in turn; each asked again as it ends.
        tasks = [self.blocks_view(stop)]
        if blocks:
            tasks.append(self.keep_running("blocks run", blocks, stop, 1000, 0.0))
        if flood:
            flooders = range(plan.floods_at_once)
            tasks += [self.keep_running("flood", flood, stop, plan.floods, 0.3) for _ in flooders]
        if hog:
            hogs = range(plan.hogs)
            tasks += [self.keep_running("hog", hog, stop, 10 * plan.hogs, 0.6) for _ in hogs]
        try:
            await asyncio.gather(*tasks)
        finally:
            watcher.cancel()

    async def create(self, kind: str, name: str, language: str, source: str) -> int | None:
        t = time.perf_counter()
        body = {"name": name, "language": language, "source": source}
        answer = await self.api.post("/api/programs", json=body)
        if answer.status_code == 201:
            return answer.json()["id"]
        said = f"program refused at save: HTTP {answer.status_code} {short(answer.text)}"
        self.answers[kind].append((said, time.perf_counter() - t))
        return None

    async def blocks_view(self, stop: asyncio.Event) -> None:
        """(1) to the read-only pane's view, one request after another."""
        path = f"/programs/{self.view_program}/blocks/python"
        while not stop.is_set():
            t = time.perf_counter()
            try:
                form = {"source": self.plan.blocks_json}
                answer = await self.session.http.post(path, data=form, timeout=ATTACK_TIMEOUT)
                said = f"HTTP {answer.status_code}: {view_answer(answer)}"
            except httpx.HTTPError as exc:
                said = type(exc).__name__
            self.answers["blocks view"].append((said, time.perf_counter() - t))
            await asyncio.sleep(0.2)

    async def keep_running(
        self, kind: str, program: int, stop: asyncio.Event, most: int, delay: float
    ) -> None:
        """One run of the kind in flight, asked again when it ends, `most` in all."""
        await asyncio.sleep(delay)
        while not stop.is_set() and self.launched[kind] < most:
            self.launched[kind] += 1
            await self.launch_and_follow(kind, program, stop)

    async def launch_and_follow(self, kind: str, program: int, stop: asyncio.Event) -> None:
        """Ask a run and follow it (watch_runs reads its state) to its end or the attack's."""
        t = time.perf_counter()
        try:
            path, body = f"/api/programs/{program}/run", {"robot": self.plan.robot}
            answer = await self.api.post(path, json=body)
        except httpx.HTTPError as exc:
            said = f"run request: {type(exc).__name__}"
            self.answers[kind].append((said, time.perf_counter() - t))
            await asyncio.sleep(1.0)
            return
        if answer.status_code != 201:
            said = f"run refused: HTTP {answer.status_code} {short(answer.text)}"
            self.answers[kind].append((said, time.perf_counter() - t))
            await asyncio.sleep(1.0)
            return
        run = answer.json()
        self.kind_of[run["id"]] = kind
        self.note(run)
        while not stop.is_set() and self.runs[run["id"]]["state"] not in ENDED:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 0.5)
        last = self.runs[run["id"]]
        if last["state"] in ("failed", "lost"):
            reason = await why_not_finished(self.api, run["id"])
        else:
            reason = f" ({short(last['reason'], 90)})" if last.get("reason") else ""
        still = "" if last["state"] in ENDED else ", still so when the attack ended"
        said = "HTTP 201, " + " -> ".join(self.seen[run["id"]]) + reason + still
        self.answers[kind].append((said, time.perf_counter() - t))

    def note(self, run: dict) -> None:
        self.runs[run["id"]] = run
        seen = self.seen.setdefault(run["id"], [])
        if not seen or seen[-1] != run["state"]:
            seen.append(run["state"])

    async def watch_runs(self) -> None:
        """The attacker's runs, twice a second: how many of each kind ran at once, why queued."""
        while True:
            with contextlib.suppress(httpx.HTTPError, ValueError):
                running: Counter = Counter()
                for run in (await self.api.get("/api/runs", params={"limit": 200})).json():
                    kind = self.kind_of.get(run["id"])
                    if kind is None:
                        continue
                    self.note(run)
                    if run["state"] == "running":
                        running[kind] += 1
                    elif run["state"] == "queued":
                        self.queued_reasons[f"{kind}: {short(run['reason'], 120)}"] += 1
                running["all kinds together"] = sum(running.values())
                for kind, count in running.items():
                    self.most_running[kind] = max(self.most_running[kind], count)
            await asyncio.sleep(0.5)

    async def stop_runs(self) -> None:
        """Whatever is still running or waiting is stopped (the attack phase is over)."""
        for run_id, run in list(self.runs.items()):
            if run["state"] not in ENDED:
                with contextlib.suppress(httpx.HTTPError):
                    await self.api.post(f"/api/runs/{run_id}/stop", timeout=30)

    async def close(self) -> None:
        await self.api.aclose()
        await self.session.close()


def view_answer(answer: httpx.Response) -> str:
    try:
        body = answer.json()
    except ValueError:
        return short(answer.text)
    if "python" in body:
        return f"{len(body['python']) / 1e6:.1f} MB of Python"
    return short(json.dumps(body), 120)


def short(text: str, most: int = 80) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= most else text[: most - 1] + "…"
