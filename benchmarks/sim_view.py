"""One viewer of a moving sim: what the server pays for the JPEG it draws against the pose
stream the browser draws from (issue 30, "Drawn in the browser").

    .venv/bin/python -m benchmarks.sim_view [--seconds 6]

One embedded appliance; its `sim` robot drives in a circle (a program run on it), and is
watched in four phases of WINDOW seconds each, ROUNDS times in turn (each figure the median
round), the server's CPU (all its threads, % of one CPU) measured over each:
- nobody: the robot moves, no page is open;
- websocket alone: what a scripts-on robot page opens now (/ws/robots/sim/: 4 telemetry
  messages a second, and robot.pose up to 20 a second while the robot moves, which the
  browser draws from at its display's rate);
- MJPEG alone: the server-drawn view (/robots/sim/camera.mjpg, 10 JPEGs a second at most),
  what a page without scripts still gets;
- websocket + MJPEG: what a scripts-on robot page opened before (its websocket, here with the
  poses too, and the <img> on the JPEG stream).
Run against the code before the pose stream (a worktree of it on PYTHONPATH, this file run by
its path), "websocket alone" is the old page's websocket without poses.
Per phase: frames (JPEGs, poses) a second reaching the viewer, its bytes a second. The viewer's
cost is the phase's CPU less nobody's.
"""

from __future__ import annotations

import argparse
import threading
import time

import httpx

from benchmarks.common import (
    Figure,
    api_client,
    appliance,
    print_table,
    proc_cpu_seconds,
    say,
    session_cookie,
    ws_connect,
)

BENCH = "sim_view"
WARM = 1.5  # s for a phase's viewer to get going
WINDOW = 6.0
ROUNDS = 3  # of the four phases in turn: each figure is its phase's median round
CLOSING = b"\r\n--frame"  # after each MJPEG part
CIRCLE = """\
import robot, time
bot = robot.Robot()
bot.drive(0.2, 0.6)  # a circle of 0.33 m: clear of the boxes world's boxes
time.sleep({seconds})
bot.stop()
"""


class Socket(threading.Thread):
    """The page's websocket: counts pose frames and bytes."""

    def __init__(self, app, cookie: str):
        super().__init__(daemon=True)
        self.app, self.cookie = app, cookie
        self.poses = self.bytes = 0
        self.error = ""
        self.stop = threading.Event()

    def run(self) -> None:
        try:
            with ws_connect(self.app, "/ws/robots/sim/", self.cookie) as ws:
                while not self.stop.is_set():
                    try:
                        message = ws.recv(timeout=0.5)
                    except TimeoutError:
                        continue
                    self.bytes += len(message)
                    if message.startswith('{"type":"robot.pose"'):
                        self.poses += 1
        except Exception as exc:
            self.error = repr(exc)


class Jpeg(threading.Thread):
    """The page's <img> on the server-drawn view: counts JPEG frames and bytes."""

    def __init__(self, app, cookie: str):
        super().__init__(daemon=True)
        self.url, self.cookie = f"{app.url}/robots/sim/camera.mjpg", cookie
        self.frames = self.bytes = 0
        self.error = ""
        self.stop = threading.Event()

    def run(self) -> None:
        try:
            with (
                httpx.Client(headers={"Cookie": self.cookie}, timeout=10) as client,
                client.stream("GET", self.url) as response,
            ):
                tail = b""
                for chunk in response.iter_raw():
                    data = tail + chunk
                    self.frames += data.count(CLOSING)
                    self.bytes += len(chunk)
                    tail = data[-(len(CLOSING) - 1) :]
                    if self.stop.is_set():
                        break
        except Exception as exc:
            self.error = repr(exc)


def phase(app, cookie: str, viewers: list[threading.Thread], window: float) -> dict:
    for viewer in viewers:
        viewer.start()
    time.sleep(WARM)
    counts = [_counts(v) for v in viewers]
    cpu, t0 = proc_cpu_seconds(app.server.pid), time.monotonic()
    time.sleep(window)
    elapsed = time.monotonic() - t0
    result = {"cpu": 100.0 * (proc_cpu_seconds(app.server.pid) - cpu) / elapsed}
    for viewer, (frames, data) in zip(viewers, counts, strict=True):
        now_frames, now_bytes = _counts(viewer)
        kind = "jpeg" if isinstance(viewer, Jpeg) else "socket"
        result[kind] = {
            "fps": (now_frames - frames) / elapsed,
            "kb": (now_bytes - data) / elapsed / 1024,
        }
    for viewer in viewers:
        viewer.stop.set()
    for viewer in viewers:
        viewer.join(5)
        if viewer.error:
            raise RuntimeError(f"{type(viewer).__name__} failed: {viewer.error}")
    time.sleep(1.0)  # the camera's producer notices nobody watches
    return result


def middle(rounds: list[dict], name: str) -> dict:
    """The round whose CPU is the median of the phase's (other load on the machine skews some)."""
    ordered = sorted((r[name] for r in rounds), key=lambda r: r["cpu"])
    return ordered[len(ordered) // 2]


def _counts(viewer) -> tuple[int, int]:
    return (viewer.frames if isinstance(viewer, Jpeg) else viewer.poses), viewer.bytes


def run(window: float = WINDOW) -> list[Figure]:
    with appliance("sim_view") as app, api_client(app) as api:
        cookie = session_cookie(app)
        seconds = ROUNDS * 4 * (window + WARM + 1) + 10
        program = api.post(
            "/api/programs",
            json={"name": "Circle", "language": "python", "source": CIRCLE.format(seconds=seconds)},
        )
        program.raise_for_status()
        run_id = api.post(f"/api/programs/{program.json()['id']}/run", json={"robot": "sim"})
        run_id.raise_for_status()
        time.sleep(2.0)  # its program is going
        rounds = [
            {
                "nobody": phase(app, cookie, [], window),
                "new": phase(app, cookie, [Socket(app, cookie)], window),
                "jpeg": phase(app, cookie, [Jpeg(app, cookie)], window),
                "old": phase(app, cookie, [Socket(app, cookie), Jpeg(app, cookie)], window),
            }
            for _ in range(ROUNDS)
        ]
        nobody, new, jpeg, old = (middle(rounds, name) for name in ("nobody", "new", "jpeg", "old"))
        api.post(f"/api/runs/{run_id.json()['id']}/stop")
    say(f"moving sim, nobody watching: server CPU {nobody['cpu']:.1f} %")
    say(
        f"websocket alone (the new page): server CPU {new['cpu']:.1f} %,"
        f" {new['socket']['fps']:.1f} poses/s, {new['socket']['kb']:.1f} KB/s"
    )
    say(
        f"MJPEG alone: server CPU {jpeg['cpu']:.1f} %, {jpeg['jpeg']['fps']:.1f} JPEG/s,"
        f" {jpeg['jpeg']['kb']:.0f} KB/s"
    )
    say(
        f"websocket + MJPEG (the old page): server CPU {old['cpu']:.1f} %,"
        f" {old['jpeg']['fps']:.1f} JPEG/s, {old['jpeg']['kb'] + old['socket']['kb']:.0f} KB/s"
    )
    cost = {
        name: r["cpu"] - nobody["cpu"] for name, r in (("new", new), ("jpeg", jpeg), ("old", old))
    }
    return [
        Figure(BENCH, "moving sim, nobody watching: server CPU", nobody["cpu"], "%"),
        Figure(BENCH, "one viewer's cost, websocket alone (new page)", cost["new"], "%",
               note=f"{new['socket']['fps']:.1f} poses/s, {new['socket']['kb']:.1f} KB/s"),
        Figure(BENCH, "one viewer's cost, MJPEG alone", cost["jpeg"], "%",
               note=f"{jpeg['jpeg']['fps']:.1f} JPEG/s, {jpeg['jpeg']['kb']:.0f} KB/s"),
        Figure(BENCH, "one viewer's cost, websocket + MJPEG (old page)", cost["old"], "%",
               target="> the new page's", ok=cost["old"] > cost["new"]),
    ]  # fmt: skip


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=WINDOW, help="each phase's window")
    print_table(run(parser.parse_args().seconds), title=BENCH)
