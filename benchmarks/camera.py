"""The live camera: frames per second delivered to each viewer, and what they cost the server.

One appliance; its sim robot's camera is watched through ``GET /robots/sim/camera.mjpg`` by 1
and then 10 viewers at once (signed-in HTTP clients in threads, counting whole parts), first
with the sim's own rendered view (320x240), then with ffmpeg's test source as a configured
camera (``lavfi:testsrc`` at 640x480), both at the default cap of 10 frames per second:
- frames/s: parts received per viewer per second over the measuring window (mean, and the
  slowest viewer);
- CPU: the server process's CPU time over the window (all its threads: rendering, the channel
  layer, the stream writers), and that of its ffmpeg child for the configured camera; per
  added viewer, (CPU with 10 viewers - CPU with 1) / 9: one viewer pays for the producer;
- nobody watching: the server's CPU before any viewer and after the last one left, and the
  ffmpeg processes left behind (none: the camera costs nothing when nobody watches).
"""

import threading
import time
from pathlib import Path

import httpx

from benchmarks.common import (
    Figure,
    api_client,
    appliance,
    print_table,
    proc_cpu_seconds,
    say,
    session_cookie,
)

BENCH = "camera"
PATH = "/robots/sim/camera.mjpg"
WARM_UP = 1.5  # s: the producer starts, every viewer has its first frames
WINDOW = 4.0  # s measured
IDLE_WINDOW = 3.0
VIEWERS = (1, 10)
FPS = 10
SOURCES = {
    "sim view 320x240": {},
    "lavfi testsrc 640x480": {"device": "lavfi:testsrc", "width": 640, "height": 480},
}
CLOSING = b"\r\n--frame"  # after each part: counts whole parts received


class Viewer(threading.Thread):
    """One browser's <img>: reads the stream as fast as it comes, counting parts."""

    def __init__(self, url: str, cookie: str):
        super().__init__(daemon=True)
        self.url, self.cookie = url, cookie
        self.parts = 0
        self.bytes = 0
        self.status: int | None = None
        self.error: str = ""
        self.stop = threading.Event()

    def run(self) -> None:
        try:
            with (
                httpx.Client(headers={"Cookie": self.cookie}, timeout=10) as client,
                client.stream("GET", self.url + PATH) as response,
            ):
                self.status = response.status_code
                tail = b""
                for chunk in response.iter_raw():
                    data = tail + chunk
                    self.parts += data.count(CLOSING)
                    self.bytes += len(chunk)
                    tail = data[-(len(CLOSING) - 1) :]  # too short to hold a whole marker
                    if self.stop.is_set():
                        break
        except Exception as exc:
            self.error = repr(exc)


def ffmpeg_children(pid: int) -> list[int]:
    children = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        name = text[text.find("(") + 1 : text.rfind(")")]
        ppid = int(text.rsplit(")", 1)[1].split()[1])
        if ppid == pid and name == "ffmpeg":
            children.append(int(stat.parent.name))
    return children


def cpu_of(pids: list[int]) -> float:
    total = 0.0
    for pid in pids:
        try:
            total += proc_cpu_seconds(pid)
        except OSError:  # gone meanwhile
            pass
    return total


def cpu_percent(pid: int, seconds: float) -> float:
    start, t0 = proc_cpu_seconds(pid), time.monotonic()
    time.sleep(seconds)
    return 100.0 * (proc_cpu_seconds(pid) - start) / (time.monotonic() - t0)


def watch(app, cookie: str, n: int) -> dict:
    server = app.server.pid
    viewers = [Viewer(app.url, cookie) for _ in range(n)]
    for viewer in viewers:
        viewer.start()
    time.sleep(WARM_UP)
    children = ffmpeg_children(server)
    parts = [v.parts for v in viewers]
    cpu, child_cpu, t0 = proc_cpu_seconds(server), cpu_of(children), time.monotonic()
    time.sleep(WINDOW)
    elapsed = time.monotonic() - t0
    cpu = 100.0 * (proc_cpu_seconds(server) - cpu) / elapsed
    child_cpu = 100.0 * (cpu_of(children) - child_cpu) / elapsed
    rates = [(v.parts - before) / elapsed for v, before in zip(viewers, parts, strict=True)]
    kb = sum(v.bytes for v in viewers) / n / (WARM_UP + elapsed) / 1024
    for viewer in viewers:
        viewer.stop.set()
    for viewer in viewers:
        viewer.join(5)
    errors = {v.error or f"status {v.status}" for v in viewers if v.error or v.status != 200}
    if errors:
        raise RuntimeError(f"viewers failed: {', '.join(sorted(errors))}")
    return {
        "mean": sum(rates) / n,
        "slowest": min(rates),
        "cpu": cpu,
        "ffmpeg": child_cpu if children else None,
        "kb": kb,
    }


def run() -> list[Figure]:
    figures = []
    with appliance("camera") as app:
        cookie = session_cookie(app)
        server = app.server.pid
        time.sleep(1.0)  # the start settles
        idle = cpu_percent(server, IDLE_WINDOW)
        say(f"nobody watching: server CPU {idle:.1f} %")
        figures.append(Figure(BENCH, "server CPU, nobody watching", idle, "%"))
        with api_client(app) as api:
            for source, camera in SOURCES.items():
                settings = {"camera": {**camera, "fps": FPS}}
                response = api.patch("/api/robots/sim", json={"settings": settings})
                response.raise_for_status()
                time.sleep(0.5)  # the agent reopens the robot
                one_viewer = None
                for n in VIEWERS:
                    r = watch(app, cookie, n)
                    say(f"{source}, {n} viewer(s): {r['mean']:.1f} fps (slowest"
                        f" {r['slowest']:.1f}), {r['kb']:.0f} KB/s each, server CPU"
                        f" {r['cpu']:.1f} %, ffmpeg {r['ffmpeg'] or 0:.1f} %")  # fmt: skip
                    label = f"{source}, {n} viewer{'s' if n > 1 else ''}"
                    figures += [
                        Figure(
                            BENCH,
                            f"{label}: frames/s per viewer",
                            r["mean"],
                            "fps",
                            target=f">= {0.9 * FPS:g} (cap {FPS})",
                            ok=r["slowest"] >= 0.9 * FPS,
                            note=f"slowest viewer {r['slowest']:.1f} fps, {r['kb']:.0f} KB/s",
                        ),
                        Figure(BENCH, f"{label}: server CPU", r["cpu"], "%"),
                    ]
                    if one_viewer is None:
                        one_viewer = r["cpu"]
                    else:  # what each viewer adds to the producer and the first one
                        extra = max(0.0, r["cpu"] - one_viewer) / (n - 1)
                        figures.append(
                            Figure(BENCH, f"{source}: server CPU per added viewer", extra, "%")
                        )
                    if r["ffmpeg"] is not None:
                        figures.append(Figure(BENCH, f"{label}: ffmpeg CPU", r["ffmpeg"], "%"))
            api.patch("/api/robots/sim", json={"settings": {}})
        time.sleep(1.0)  # the last viewer's unwatch reaches the agent
        left = len(ffmpeg_children(server))
        after = cpu_percent(server, IDLE_WINDOW)
        say(f"after the last viewer left: server CPU {after:.1f} %, {left} ffmpeg process(es)")
        figures += [
            Figure(BENCH, "server CPU, nobody watching any more", after, "%",
                   target=f"<= {idle + 1:.1f} (before + 1)", ok=after <= idle + 1),
            Figure(BENCH, "ffmpeg processes once nobody watches", left, "",
                   target="0", ok=left == 0),
        ]  # fmt: skip
    return figures


if __name__ == "__main__":
    print_table(run(), title="camera")
