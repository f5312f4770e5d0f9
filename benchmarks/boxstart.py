"""A boxed start, timed: the agent's launcher chain without the web tier, one run per request.

    python3 benchmarks/boxstart.py            # then one JSON request a line on stdin

Standard library and runbox only (like tests/runbox/boxrun.py), so that the system's python3
runs it as an ordinary account too (the rootless chain: util-linux unshare + runbox.inbox);
as root it makes bubblewrap's box as robots/agent.py `_launch` does. start_overhead keeps one
of these running per account and sends it a request per start, interleaved with its other
baselines. A request::

    {"stage": "box", "command": ["/usr/bin/python3", "-u"], "source": "...",
     "filename": "main.py", "env": {...}}

stages (cumulative, root only but "bare" and "box"):
    bare                    the interpreter on the program file in a folder here, unboxed
    bwrap                   bubblewrap with the box's mounts, namespaces, folder and seccomp
                            filter, no --info-fd/--block-fd (runs at once), as root inside
    bwrap+setpriv           + setpriv into the run's account (as the launcher does)
    bwrap+setpriv+prlimit   + prlimit with the default limits
    box                     the whole chain as the agent builds it: runbox.box.make_box (with
                            the Robot API's tcp:7010 listener), launcher.command, the spawn,
                            box.open() (info-fd read, setns + bind, serve, unblock)
Each answer: {"first": spawn -> first stdout data, "prepare": box + argv built, "steps": {...},
"close": box.close() after the exit, ...}, seconds; the spawn is loop.subprocess_exec with
RunProcess's options (new session, umask 022, pass_fds, clean env, pipes).
"""

import asyncio
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from subprocess import DEVNULL, PIPE

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from runbox import launcher, seccomp  # noqa: E402
from runbox.box import BwrapBox, Listener, RootlessBox  # noqa: E402
from runbox.isolation import Policy, tool  # noqa: E402

CLIENTS = ROOT / "programs" / "clients"
now = time.perf_counter


class Timed:
    """Mixed into a box: when each step of open() ended (wrapping its methods, not copying
    open(): the steps are runbox's own)."""

    def _mark(self, name: str) -> None:
        self.marks.append((name, now()))

    async def open(self, launcher_pid: int) -> None:
        self.marks = [("open", now())]
        await super().open(launcher_pid)
        self._mark("unblocked")

    async def _read_info(self):  # BwrapBox
        info = await super()._read_info()
        self._mark("info-fd read")
        return info

    def _handshake(self, spec):  # RootlessBox, in a thread
        sockets = super()._handshake(spec)
        self._mark("inbox ready (sockets handed over)")
        return sockets

    async def _serve(self, sockets) -> None:
        self._mark("setns + bind" if isinstance(self, BwrapBox) else "first child found")
        await super()._serve(sockets)
        self._mark("served")

    def steps(self) -> dict[str, float]:
        out, (_, last) = {}, self.marks[0]
        for name, t in self.marks[1:]:
            out[name] = t - last
            last = t
        return out


class TimedBwrapBox(Timed, BwrapBox):
    pass


class TimedRootlessBox(Timed, RootlessBox):
    pass


class Language:
    def __init__(self, prefix: list[str]):
        self.prefix, self.env = prefix, {}

    def command(self, path: str) -> list[str]:
        return [*self.prefix, path]


class FirstLine(asyncio.SubprocessProtocol):
    def __init__(self):
        loop = asyncio.get_running_loop()
        self.first = loop.create_future()
        self.exited = loop.create_future()
        self.data = b""

    def pipe_data_received(self, fd, data):
        if fd == 1:
            self.data += data
            if b"\n" in self.data and not self.first.done():
                self.first.set_result(now())

    def connection_lost(self, exc):  # the pipes closed and the process ended
        if not self.first.done():
            self.first.set_result(None)
        if not self.exited.done():
            self.exited.set_result(None)


async def serve_echo(sock):
    """What the Robot API's TCP side does with its socket: an asyncio server on it."""

    async def echo(reader, writer):
        writer.write(await reader.readline())
        writer.close()

    return await asyncio.start_server(echo, sock=sock)


class Driver:
    def __init__(self):
        self.work = Path(tempfile.mkdtemp(prefix="boxstart-"))
        self.sockets = self.work / "sockets"
        self.sockets.mkdir()
        self.in_force = Policy().resolve(CLIENTS)
        self.limits = launcher.Limits()
        self.count = 0

    async def start(self, req: dict) -> dict:
        stage, source, filename = req["stage"], req["source"].encode(), req["filename"]
        language = Language(req["command"])
        env = dict(req["env"])
        in_force, limits = self.in_force, self.limits
        self.count += 1
        box = None
        fds: list[int] = []
        t0 = now()
        if stage == "bare":
            file = self.work / filename
            file.write_bytes(source)
            argv, cwd = language.command(str(file)), self.work
        elif stage == "box":
            kind = TimedRootlessBox if in_force.rootless else TimedBwrapBox
            options = {"socket_dir": self.sockets} if in_force.rootless else {}
            box = kind(
                in_force, source=source, filename=filename, disk_mb=limits.disk_mb,
                listeners=[Listener("tcp:7010", serve_echo)],
                seccomp_fd=seccomp.open_filter_fd(), **options,
            )  # fmt: skip
            argv = launcher.command(
                language, in_force.home() / filename, limits, isolation=in_force,
                uid=in_force.uid(self.count, str(self.work)), socket_dir=self.sockets,
                box_args=box.args(),
            )  # fmt: skip
            cwd = self.work
        else:
            if in_force.rootless:
                raise ValueError(f"stage {stage} is root's only")
            program = os.memfd_create("program", 0)
            os.write(program, source)
            os.lseek(program, 0, os.SEEK_SET)
            filter_fd = seccomp.open_filter_fd()
            fds = [program, filter_fd]
            inner = language.command(str(in_force.home() / filename))
            if "prlimit" in stage:
                inner = [tool("prlimit"), *limits.prlimit_args(), "--", *inner]
            if "setpriv" in stage:
                uid = in_force.uid(self.count, str(self.work))
                inner = [
                    tool("setpriv"), f"--reuid={uid}", f"--regid={uid}", "--clear-groups",
                    "--no-new-privs", "--", *inner,
                ]  # fmt: skip
            argv = [
                *in_force.bwrap(self.sockets), "--seccomp", str(filter_fd),
                *in_force.folder_args(limits.disk_mb, program, filename), "--", *inner,
            ]  # fmt: skip
            cwd = self.work
        t_prepared = now()
        loop = asyncio.get_running_loop()
        transport, proto = await loop.subprocess_exec(
            FirstLine, *argv, stdin=DEVNULL, stdout=PIPE, stderr=PIPE, cwd=cwd, env=env,
            start_new_session=True, umask=0o022,
            pass_fds=box.pass_fds() if box else tuple(fds),
        )  # fmt: skip
        t_spawned = now()
        for fd in fds:
            os.close(fd)
        if box is not None:
            await box.open(transport.get_pid())
        t_opened = now()
        first = await asyncio.wait_for(proto.first, 10)
        await asyncio.wait_for(proto.exited, 10)
        transport.close()
        t_exit = now()
        if box is not None:
            await box.close()
        t_closed = now()
        return {
            "stage": stage,
            "first": None if first is None else first - t_prepared,
            "prepare": t_prepared - t0,
            "spawn": t_spawned - t_prepared,
            "open": t_opened - t_spawned,
            "steps": box.steps() if box is not None else {},
            "close": t_closed - t_exit,
            "output": proto.data.decode(errors="replace")[:200],
            "rootless": in_force.rootless,
            "returncode": transport.get_returncode(),
        }


async def main() -> None:
    driver = Driver()
    loop = asyncio.get_running_loop()
    print(json.dumps({"ready": True, "rootless": driver.in_force.rootless}), flush=True)
    try:
        while line := await loop.run_in_executor(None, sys.stdin.readline):
            try:
                answer = await driver.start(json.loads(line))
            except Exception as exc:
                answer = {"error": repr(exc)}
            print(json.dumps(answer), flush=True)
    finally:
        shutil.rmtree(driver.work, ignore_errors=True)


if __name__ == "__main__":
    asyncio.run(main())
