"""A boxed start, timed: the agent's launcher chain without the web tier, one run per request.

    python3 benchmarks/boxstart.py            # then one JSON request a line on stdin

Standard library and runbox only (like tests/runbox/boxrun.py), so that the system's python3
runs it as an ordinary account too (the rootless chain: util-linux unshare + runbox.inbox);
as root it makes bubblewrap's box as robots/agent.py `_launch` does. start_overhead keeps one
of these running per account and sends it a request per start, interleaved with its other
baselines. A request::

    {"stage": "box", "command": ["/usr/bin/python3", "-u"], "source": "...",
     "filename": "main.py", "env": {...}}

stages (cumulative, root only but "bare", "box" and "ahead"):
    bare                    the interpreter on the program file in a folder here, unboxed
    bwrap                   bubblewrap with the box's mounts, namespaces, folder and seccomp
                            filter, no --info-fd/--block-fd (runs at once), as root inside
    bwrap+setpriv           + setpriv into the run's account (as the launcher does)
    bwrap+setpriv+prlimit   + prlimit with the default limits
    box                     the whole chain as the agent builds it when no box is ready:
                            runbox.box.make_box (with the Robot API's tcp:7010 listener), the
                            spawn, box.prepare() (info-fd read, setns + bind, serve, unblock),
                            box.go() (the script to the box's waiting shell)
    ahead                   a box made and prepared before the request (not timed), as the
                            agent keeps one: only box.go() and what follows
Each answer: {"first": spawn (ahead: go) -> first stdout data, "prepare": box + argv built,
"steps": {...}, "close": box.close() after the exit, ...}, seconds; the spawn is
loop.subprocess_exec with RunProcess's options (new session, umask 022, pass_fds, clean env,
pipes).
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

from runbox import SYSTEM_PATH, launcher, seccomp  # noqa: E402
from runbox.box import BwrapBox, Launch, Listener, RootlessBox  # noqa: E402
from runbox.isolation import Policy, tool  # noqa: E402

CLIENTS = ROOT / "programs" / "clients"
now = time.perf_counter


class Timed:
    """Mixed into a box: when each step of prepare() and go() ended (wrapping its methods,
    not copying them: the steps are runbox's own)."""

    def _mark(self, name: str) -> None:
        self.marks.append((name, now()))

    async def prepare(self, launcher_pid: int, wait_for_cgroup: bool = True) -> None:
        self.marks = [("prepare", now())]
        await super().prepare(launcher_pid, wait_for_cgroup)
        self._mark("unblocked")

    async def go(self, launch, gate=None) -> None:
        await super().go(launch, gate)
        self._mark("program handed over")

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
        stage = req["stage"]
        if stage in ("box", "ahead"):
            return await self.boxed(req, ahead=stage == "ahead")
        source, filename = req["source"].encode(), req["filename"]
        language = Language(req["command"])
        in_force, limits = self.in_force, self.limits
        self.count += 1
        fds: list[int] = []
        t0 = now()
        if stage == "bare":
            file = self.work / filename
            file.write_bytes(source)
            argv = language.command(str(file))
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
                inner = in_force.program_command(inner, in_force.uid(self.count, str(self.work)))
            argv = [
                *in_force.bwrap(self.sockets), "--seccomp", str(filter_fd),
                *in_force.folder_args(limits.disk_mb), "--perms", "0644",
                "--file", str(program), str(in_force.home() / filename), "--", *inner,
            ]  # fmt: skip
        t_prepared = now()
        transport, proto = await self.spawn(argv, req["env"], DEVNULL, tuple(fds))
        t_spawned = now()
        for fd in fds:
            os.close(fd)
        return await self.finish(stage, transport, proto, t0, t_prepared, t_spawned, t_spawned)

    async def spawn(self, argv, env, stdin, pass_fds):
        loop = asyncio.get_running_loop()
        return await loop.subprocess_exec(
            FirstLine, *argv, stdin=stdin, stdout=PIPE, stderr=PIPE, cwd=self.work, env=env,
            start_new_session=True, umask=0o022, pass_fds=pass_fds,
        )  # fmt: skip

    async def boxed(self, req: dict, ahead: bool) -> dict:
        """As the agent: a box made (ahead: before the clock starts), then the run's go()."""
        in_force, limits = self.in_force, self.limits
        self.count += 1
        t0 = now()
        box = (TimedRootlessBox if in_force.rootless else TimedBwrapBox)(
            in_force, socket_dir=self.sockets, disk_mb=limits.disk_mb,
            listeners=[Listener("tcp:7010", serve_echo)], seccomp_fd=seccomp.open_filter_fd(),
        )  # fmt: skip
        argv = in_force.program_command(
            Language(req["command"]).command(str(in_force.home() / req["filename"])),
            in_force.uid(self.count, str(self.work)),
        )
        launch = Launch(req["filename"], req["source"].encode(), argv, dict(req["env"]))
        t_prepared = now()
        transport, proto = await self.spawn(
            box.command(), {"PATH": SYSTEM_PATH}, box.stdin() or DEVNULL, box.pass_fds()
        )
        t_spawned = now()
        await box.prepare(transport.get_pid(), wait_for_cgroup=ahead)
        if ahead:
            await asyncio.sleep(0.05)  # the box waits, as one made ahead does
            t_prepared = t_spawned = now()
            box.marks = [("go", t_prepared)]
        await box.go(launch)
        t_opened = now()
        try:
            return await self.finish(
                req["stage"], transport, proto, t0, t_prepared, t_spawned, t_opened, box
            )
        finally:
            box.kill()
            await box.close()

    async def finish(self, stage, transport, proto, t0, t_prepared, t_spawned, t_opened, box=None):
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
            "rootless": self.in_force.rootless,
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
