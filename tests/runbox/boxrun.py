"""Run one program in a box, as the agent would, and print what happened as JSON.

    python3 boxrun.py '{"source": "...", "network": "loopback", "limits": {...}}'

More: "args" (the program's), "speed" (its clock's, as a sim's: runbox.timescale), "ahead"
(seconds the box waits, made, before its run is given), "refuse" (the gate's answer),
"stop_after", "grace"; "stop_on" (stopped as its user would, once it printed a line holding
this text and, with "stop_on_peak_mb", once the watch has sampled at least that much memory).

Standard library and runbox only, so that an ordinary user's python3 runs it too (the
rootless box); the Robot API is stood in for by a TCP echo on the run's 127.0.0.1:7010.
"""

import asyncio
import json
import socket
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from runbox import SYSTEM_PATH, launcher, seccomp, timescale  # noqa: E402
from runbox.box import Launch, Listener, make_box  # noqa: E402
from runbox.cgroups import CgroupSupport, detect  # noqa: E402
from runbox.isolation import Policy  # noqa: E402
from runbox.supervisor import RunProcess  # noqa: E402
from runbox.watch import RunWatch  # noqa: E402

PYTHON = type("Python", (), {
    "command": lambda self, path: ["/usr/bin/python3", path], "env": {},
    "client_env": lambda self, clients=None: {},
})()  # fmt: skip


class Echo:
    """Answers a connection on the run's 127.0.0.1:7010 with what it sent."""

    async def serve(self, sock):
        return await asyncio.start_server(self.echo, sock=sock)

    async def echo(self, reader, writer):
        writer.write(await reader.readline())
        await writer.drain()
        writer.close()


async def run(spec: dict) -> dict:
    policy = Policy.from_settings({"network": spec.get("network", "loopback")})
    folder = Path(tempfile.mkdtemp(prefix="boxrun-"))
    clients = folder / "clients"
    clients.mkdir()
    sockets = folder / "sockets"
    sockets.mkdir()
    api = listen_as_the_agent(sockets / "api.sock")
    in_force = policy.resolve(clients, cgroups_here())
    limits = launcher.Limits.from_settings(spec.get("limits", {}))
    listeners = [] if policy.network == "none" else [Listener("tcp:7010", Echo().serve)]
    box = make_box(
        in_force, socket_dir=sockets, disk_mb=limits.disk_mb, listeners=listeners,
        seccomp_fd=seccomp.open_filter_fd(), rlimits=limits.rlimits(),
    )  # fmt: skip
    program = ["/usr/bin/python3", str(in_force.home() / "main.py"), *spec.get("args", ())]
    argv = in_force.program_command(
        timescale.command(program, spec.get("speed", 1)),  # a sim's speed: its clock
        in_force.uid(int(time.time()) % 100_000, str(folder)),
    )
    env = launcher.environment(PYTHON, in_force.home(), {})
    launch = Launch("main.py", spec["source"].encode(), argv, env)
    lines = []
    process = RunProcess(
        box.command(), env={"PATH": SYSTEM_PATH}, cwd=folder,
        log_path=folder / "output.log", on_output=lambda batch, *_: lines.extend(batch),
        watch=RunWatch(limits, box), box=box, grace=float(spec.get("grace", 1.0)),
    )  # fmt: skip
    started = time.monotonic()

    async def gate():  # what the agent's claim of the run says, just before the program runs
        return ("stopped", spec["refuse"]) if spec.get("refuse") else None

    if spec.get("ahead"):  # the box made first, the run given to it later (as the agent does)
        await process.spawn()
        await asyncio.sleep(spec["ahead"])
        await process.begin(launch, gate)
    else:
        await process.start(gate, launch)
    if spec.get("stop_after"):
        await asyncio.sleep(spec["stop_after"])
        process.stop()
    if spec.get("stop_on"):
        await stopped_on(process, lines, spec["stop_on"], spec.get("stop_on_peak_mb", 0))
    outcome = await process.wait()
    await box.close()
    left = box.processes()
    log = (folder / "output.log").read_text()
    return {
        "state": outcome.state, "exit_code": outcome.exit_code, "reason": outcome.reason,
        "log": log, "seconds": time.monotonic() - started, "left": left,
        "rootless": in_force.rootless, "started": process.started,
        "api_folder": api_folder_after(sockets, api),
        "isolation": in_force.describe(limits), "runs_at_once": in_force.runs_at_once,
    }  # fmt: skip


async def stopped_on(process, lines, text: str, peak_mb: int, deadline: float = 60.0) -> None:
    """Stops the run once it printed `text` and its watch sampled `peak_mb` MB at least."""
    give_up = time.monotonic() + deadline
    while True:
        printed = any(text in line_text for _, _, line_text in lines)
        if printed and process.watch.peaks.memory >= peak_mb * 1024 * 1024:
            break
        if time.monotonic() > give_up:
            raise TimeoutError(f"no {text!r} and {peak_mb} MB sampled: {lines[-5:]}")
        await asyncio.sleep(0.01)
    process.stop()


def cgroups_here() -> CgroupSupport:
    """What this machine says of cgroups, but never available: the runs here get none."""
    support = detect()
    return CgroupSupport(None, why="boxrun makes no cgroups") if support.available else support


def listen_as_the_agent(path: Path) -> socket.socket:
    """The Robot API's Unix socket, its folder and modes as robots/agent.py makes them."""
    api = socket.socket(socket.AF_UNIX)
    api.bind(str(path))
    api.listen(5)
    path.parent.chmod(0o711)
    path.chmod(0o666)
    return api


def api_folder_after(sockets: Path, api: socket.socket) -> dict:
    """The socket's folder as the host sees it after the run: its files, mode, and whether
    the socket still reaches the agent's listener."""
    client = socket.socket(socket.AF_UNIX)
    try:
        client.connect(str(sockets / "api.sock"))
        api.accept()[0].close()
        reaches = True
    except OSError:
        reaches = False
    finally:
        client.close()
    return {
        "files": sorted(p.name for p in sockets.iterdir()),
        "mode": oct(sockets.stat().st_mode & 0o7777),
        "reaches": reaches,
    }


if __name__ == "__main__":
    socket.setdefaulttimeout(10)
    print(json.dumps(asyncio.run(run(json.loads(sys.argv[1])))))
