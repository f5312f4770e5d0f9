"""One run's box, made before its run is known and handed the program when the run starts.

bubblewrap writes the sandbox's first process and its namespaces to ``--info-fd`` and then
waits on ``--block-fd``. Meanwhile the agent puts that process in the box's cgroup (all the
program's processes are born inside it), opens in the box's network namespace the sockets its
robot gives programs, and starts the NAT of a `full` run (``prepare``). The sandbox then runs
a shell that waits for its script: the program's file and command come with the run (``go``).
An agent keeps one box prepared ahead per robot, so that a run's start costs only the last
step: the namespaces, the cgroup and the sockets are made while nobody waits.

The sandbox's first process is pid 1 of the run's pid namespace: killing it ends every
process of the run at once, whatever they did to hide (setsid, double fork, ignored signals).
"""

import asyncio
import base64
import contextlib
import inspect
import json
import logging
import os
import re
import resource
import select
import shlex
import signal
import socket
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path

from runbox import cgroups, netns, oom
from runbox.isolation import InForce, tool
from runbox.netspec import blocked_ranges, host_addresses

log = logging.getLogger(__name__)

INFO_MAX = 64 * 1024
NAT_READY_TIMEOUT = 10.0
INBOX_TIMEOUT = 10.0
GONE_TIMEOUT = 5.0
GATHER_ROUNDS = 20
# Whether the kernel lists each thread's children (/proc/PID/task/TID/children).
CHILDREN_LISTED = os.path.exists(f"/proc/{os.getpid()}/task/{os.getpid()}/children")


class BoxFailed(RuntimeError):
    pass


class NotStarted(Exception):
    """The gate said no: args are the run's (state, reason)."""


async def _pass(gate) -> None:
    if gate is not None and (verdict := await gate()) is not None:
        raise NotStarted(*verdict)


@dataclass(frozen=True)
class Launch:
    """What a box runs once its run starts: the program's file in the run's folder, and the
    command line and environment that run it (as root, setpriv into the run's account first)."""

    filename: str
    source: bytes
    argv: list[str]
    env: dict[str, str]


ENV_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def shell_script(launch: Launch, home: Path) -> bytes:
    """The waiting shell's script (it runs as the box's root, before the run's account):
    stdin from /dev/null again, the program's file, the run's environment and nothing else
    (dash would add PWD), then the program."""
    bad = [name for name in launch.env if not ENV_NAME.fullmatch(name)]
    if bad:
        raise ValueError(f"not an environment variable's name: {bad[0]!r}")
    if b"\0" in launch.source:
        raise ValueError("a program's text cannot hold NUL bytes")
    source = shlex.quote(launch.source.decode("utf-8", "surrogateescape"))
    lines = [
        "exec </dev/null",
        f"printf '%s' {source} >{shlex.quote(str(home / launch.filename))} || exit 126",
    ]
    if "PWD" not in launch.env:
        lines.append("unset PWD")
    if launch.env:
        lines.append("export " + " ".join(f"{k}={shlex.quote(v)}" for k, v in launch.env.items()))
    lines.append("exec " + shlex.join(launch.argv))
    return ("\n".join(lines) + "\n").encode("utf-8", "surrogateescape")


@dataclass(frozen=True)
class Listener:
    """A service on the run's 127.0.0.1: "tcp:PORT" or "udp:PORT", and what serves the socket
    made for it there (returns something with ``async close()``)."""

    service: str
    serve: Callable[[object], Awaitable[object]]


class Box:
    """What every box has: its sockets, its processes, its end; the program comes with go()."""

    def __init__(
        self,
        in_force: InForce,
        *,
        socket_dir: Path,
        disk_mb: int,
        listeners: list[Listener] = (),
        cgroup=None,
        seccomp_fd: int | None = None,
        rlimits: dict[int, tuple[int, int]] | None = None,
    ):
        """`rlimits`: each of the run's processes' own limits (resource.RLIMIT_*), set on the
        box's first process before anything runs in it; `cgroup`: a runbox.cgroups.RunCgroup
        that the box's first process joins then; `socket_dir`: the Robot API's socket folder."""
        self.in_force, self.listeners, self.cgroup = in_force, list(listeners), cgroup
        self.socket_dir = socket_dir
        self.rlimits = rlimits or {}
        self.seccomp_fd = seccomp_fd
        # Closed once done with, or at close() whatever happened in between.
        self._fds = {seccomp_fd} if seccomp_fd is not None else set()
        self.disk_mb = disk_mb
        self.init_pid: int | None = None
        self.init_fd: int | None = None  # a pidfd of it
        self.pidns: int | None = None
        self.served: list = []
        self.nat: asyncio.subprocess.Process | None = None
        self._joining: asyncio.Future | None = None  # the processes joining the cgroup

    def stdin(self) -> int | None:
        """What its first process reads (None: /dev/null)."""
        return None

    async def _enter_cgroup(self, wait: bool) -> None:
        """`wait`: the box's first process joins now, before anything of it runs (nothing
        else is there yet: no look for strays); else while the program starts."""
        if self.cgroup is None:
            return
        if wait:
            await asyncio.to_thread(self.cgroup.add, self.init_pid)
        else:
            self._join_cgroup()

    def _join_cgroup(self) -> None:
        """The run's processes join its cgroup, in a thread, while the program starts.

        On cgroup v1 a move waits for an RCU grace period: 6 to 20 ms, longer than the rest
        of a start. Waiting for it would double a shell's start; not waiting leaves a few
        milliseconds in which the program runs under its per-process limits alone, and
        whatever it forked meanwhile is gathered into the cgroup as well (the watcher looks
        again every sample)."""
        if self.cgroup is not None:
            self._joining = asyncio.ensure_future(asyncio.to_thread(self.gather))

    def gather(self) -> list[int]:
        """Move every process of the run that is not fully in its cgroup into it; returns
        those moved. Their forks made during a move are caught by the next round."""
        moved: list[int] = []
        for _ in range(GATHER_ROUNDS):
            inside = self.cgroup.members()
            strays = [p for p in (self.init_pid, *self.processes()) if p not in inside]
            if not strays:
                break
            for pid in strays:
                with contextlib.suppress(cgroups.CgroupError):  # it has just exited
                    self.cgroup.add(pid)
                    moved.append(pid)
        return moved

    async def _serve(self, sockets: list[socket.socket]) -> None:
        for listener, sock in zip(self.listeners, sockets, strict=True):
            self.served.append(await listener.serve(sock))

    # -- while it runs ----------------------------------------------------------------------

    @property
    def folder(self) -> Path | None:
        """The run's folder as the agent reaches it (its tmpfs lives in the run's mounts)."""
        if self.init_pid is None:
            return None
        return Path(f"/proc/{self.init_pid}/root") / str(self.in_force.HOME).lstrip("/")

    def processes(self) -> list[int]:
        """The program's processes: those in the run's pid namespace, but its first.

        Every process of a pid namespace descends from its first (an orphan is adopted by
        it), so a walk down its children lists finds them all, in the run's own processes'
        time: looking at every process of the machine instead, twice a second for each run
        watched, took most of a server's CPU once 30 runs went at once."""
        if self.pidns is None:
            return []
        if not CHILDREN_LISTED:
            return self._processes_in_namespace()
        found, parents = [], [self.init_pid]
        while parents:
            children = _children_of(parents.pop())
            found += children
            parents += children
        return found

    def _processes_in_namespace(self) -> list[int]:
        """processes() where the kernel lists no children (CONFIG_PROC_CHILDREN off)."""
        found = []
        for entry in os.scandir("/proc"):
            if entry.name.isdigit() and int(entry.name) != self.init_pid:
                with contextlib.suppress(OSError):
                    if os.stat(f"/proc/{entry.name}/ns/pid").st_ino == self.pidns:
                        found.append(int(entry.name))
        return found

    def signal(self, sig: int) -> None:
        if sig == signal.SIGKILL:
            self.kill()
            return
        for pid in self.processes():
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)

    def kill(self) -> None:
        """Every process of the run, at once: the end of its pid namespace's first process
        takes all the others with it (the kernel kills them; none can leave the namespace).
        Through a pidfd: never another process that got the number after it."""
        if self.init_fd is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                signal.pidfd_send_signal(self.init_fd, signal.SIGKILL)

    # -- after the end ----------------------------------------------------------------------

    async def close(self) -> None:
        """After the program's end: whatever of the run is still there ends now (the
        kernel ends a pid namespace's processes one by one), then its sockets, NAT and
        cgroup go."""
        if self._joining is not None:
            await asyncio.gather(self._joining, return_exceptions=True)
        deadline = time.monotonic() + GONE_TIMEOUT
        while (
            self._init_alive()
            and await asyncio.to_thread(self.processes)
            and time.monotonic() < deadline
        ):
            self.kill()
            await asyncio.sleep(0.01)
        for served in self.served:
            with contextlib.suppress(Exception):
                closing = served.close()  # an asyncio.Server closes at once
                if inspect.isawaitable(closing):
                    await closing
        self.served = []
        if self.nat is not None and self.nat.returncode is None:
            self.nat.kill()
            await self.nat.wait()
        if self.cgroup is not None:
            await asyncio.to_thread(self.cgroup.remove)
        self._close(*self._fds)
        self.init_fd = None  # closed with the rest: its number may be anyone's now

    async def _start_nat(self, *options: str) -> None:
        """slirp4netns for the run's network namespace (its tap0 made, not yet set up). It
        parses every packet the run sends (libslirp): sandboxed (a mount namespace of its
        own, no capability but binding low ports) and under its own seccomp filter."""
        ready_r, ready_w = os.pipe()
        try:
            self.nat = await asyncio.create_subprocess_exec(
                tool("slirp4netns"), "--mtu=65520", "--disable-host-loopback",
                "--enable-sandbox", "--enable-seccomp", *options,
                "--ready-fd", str(ready_w), str(self.init_pid), "tap0",
                pass_fds=(ready_w,), stdin=asyncio.subprocess.DEVNULL,
                stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
            )  # fmt: skip
            # The run's traffic grows it: the OOM killer's choice with the run, not the
            # agent's -500 it inherited (raising one's child's score needs no privilege).
            with contextlib.suppress(OSError):
                oom.first_to_go_now(self.nat.pid)
            os.close(ready_w)
            ready_w = None
            reading = asyncio.to_thread(os.read, ready_r, 1)
            ready = await asyncio.wait_for(reading, NAT_READY_TIMEOUT)
            if not ready:
                raise BoxFailed("slirp4netns could not set up the run's network")
        finally:
            os.close(ready_r)
            if ready_w is not None:
                os.close(ready_w)

    def _init_alive(self) -> bool:
        """Whether the run's pid namespace may still hold processes: its first process ends
        last (the kernel ends and reaps the others first), so once it has ended none are
        left; no look through /proc is needed. Its pidfd is readable once it has ended."""
        if self.init_fd is None:
            return self.init_pid is not None
        return not select.select([self.init_fd], [], [], 0)[0]

    def _adopt_init(self, pid: int) -> None:
        """The run's first process, held by a pidfd from now on."""
        self.init_pid = pid
        with contextlib.suppress(OSError):  # gone already: nothing to hold
            self.init_fd = os.pidfd_open(pid)
            self._fds.add(self.init_fd)

    def _close(self, *fds: int) -> None:
        for fd in fds:
            if fd in self._fds:
                self._fds.discard(fd)
                os.close(fd)


def _children_of(pid: int) -> list[int]:
    """A process's children, those of each of its threads (none: it has just ended)."""
    children: list[int] = []
    with contextlib.suppress(OSError):
        for tid in os.listdir(f"/proc/{pid}/task"):
            with contextlib.suppress(OSError), open(f"/proc/{pid}/task/{tid}/children") as f:
                children += map(int, f.read().split())
    return children


class BwrapBox(Box):
    """The box of an agent that is root: bubblewrap makes it, the agent opens its sockets
    from outside (runbox.netns); a shell in it waits for its script on its stdin."""

    # -- before the start -----------------------------------------------------------------

    def __init__(self, in_force: InForce, **options):
        super().__init__(in_force, **options)
        self.info_r, self.info_w = os.pipe()
        self.block_r, self.block_w = os.pipe()
        self.script_r, self.script_w = os.pipe()
        self._fds |= {self.info_r, self.info_w, self.block_r, self.block_w}
        self._fds |= {self.script_r, self.script_w}
        self.resolv_r = None
        if in_force.network == "full":  # bubblewrap copies it into the box from a pipe
            self.resolv_r, resolv_w = os.pipe()
            self._fds.add(self.resolv_r)
            os.write(resolv_w, netns.NAT_RESOLV_CONF.encode())
            os.close(resolv_w)

    def command(self) -> list[str]:
        """bubblewrap, then a shell that reads its script (the run's) from its stdin."""
        args = ["--info-fd", str(self.info_w), "--block-fd", str(self.block_r)]
        if self.seccomp_fd is not None:
            args += ["--seccomp", str(self.seccomp_fd)]
        if self.resolv_r is not None:
            args += self.in_force.resolv_conf_args(self.resolv_r)
        return [
            *self.in_force.bwrap(self.socket_dir), *args,
            *self.in_force.folder_args(self.disk_mb), "--", "/bin/sh", "-c", ". /dev/stdin",
        ]  # fmt: skip

    def pass_fds(self) -> tuple[int, ...]:
        fds = (self.info_w, self.block_r, self.seccomp_fd, self.resolv_r)
        return tuple(fd for fd in fds if fd is not None)

    def stdin(self) -> int:
        return self.script_r

    # -- between bubblewrap's start and the run's -----------------------------------------

    async def prepare(self, launcher_pid: int, wait_for_cgroup: bool = True) -> None:
        """Once bubblewrap runs: limits, cgroup, sockets, NAT; then its shell may wait.
        `wait_for_cgroup` False: the run's processes join its cgroup while they start."""
        self._close(*self.pass_fds(), self.script_r)  # the sandbox has them now
        info = await self._read_info()
        self._adopt_init(info["child-pid"])
        self.pidns = info["pid-namespace"]
        oom.first_to_go_now(self.init_pid)  # before it forks the run's shell: all inherit it
        for limit, values in self.rlimits.items():
            resource.prlimit(self.init_pid, limit, values)
        await self._enter_cgroup(wait_for_cgroup)
        if self.in_force.network != "none":
            await self._open_loopback()
        if self.in_force.network == "full":
            await self._open_nat()
        os.write(self.block_w, b"go")
        self._close(self.block_w)

    async def go(self, launch: Launch, gate=None) -> None:
        """The run's program: its file and command, to the waiting shell."""
        try:
            script = shell_script(launch, self.in_force.HOME)
            await _pass(gate)
            view = memoryview(script)
            while view:  # the shell reads as it goes: a long script does not block for long
                view = view[os.write(self.script_w, view) :]
        except BrokenPipeError:
            raise BoxFailed("the box ended before its program could start") from None
        finally:
            self._close(self.script_w)

    async def _read_info(self) -> dict:
        loop = asyncio.get_running_loop()
        data = b""
        try:
            while len(data) < INFO_MAX:
                ready = loop.create_future()
                loop.add_reader(self.info_r, ready.set_result, None)
                try:
                    await ready
                finally:
                    loop.remove_reader(self.info_r)
                chunk = os.read(self.info_r, 4096)
                if not chunk:
                    break
                data += chunk
                with contextlib.suppress(ValueError):
                    return json.loads(data)
        finally:
            self._close(self.info_r)
        raise BoxFailed("bubblewrap ended before its sandbox was made (see the log)")

    async def _open_loopback(self) -> None:
        services = [listener.service for listener in self.listeners]
        sockets = await asyncio.wrap_future(
            netns.in_namespace(self.init_pid, lambda: netns.bind_loopback(services))
        )
        await self._serve(sockets)

    async def _open_nat(self) -> None:
        """slirp4netns: the run's own tap device, NAT to the internet, never to the host's
        loopback; then routes that refuse the private ranges the robot does not allow.
        The tap device is set up here, not by slirp4netns (whose set-up of the loopback
        would clash with bubblewrap's)."""
        await self._start_nat()
        ranges = blocked_ranges(self.in_force.policy.allow_networks, host_addresses())
        await asyncio.wrap_future(
            netns.in_namespace(self.init_pid, lambda: netns.configure_nat(tool("ip"), ranges))
        )


class RootlessBox(Box):
    """The box of an agent that is not root: runbox.inbox makes it from the inside and hands
    the run's sockets over its control socket; the run's program and command follow there."""

    def __init__(self, in_force: InForce, **options):
        super().__init__(in_force, **options)
        self.control, theirs = socket.socketpair()
        self.theirs = theirs.detach()
        self._fds.add(self.theirs)
        self.spec = in_force.inbox_spec(self.socket_dir, self.disk_mb)

    def command(self) -> list[str]:
        return oom.first_to_go([*self.in_force.unshare(), str(self.theirs)], tool("choom"))

    def pass_fds(self) -> tuple[int, ...]:
        return (self.theirs,) if self.seccomp_fd is None else (self.theirs, self.seccomp_fd)

    async def prepare(self, launcher_pid: int, wait_for_cgroup: bool = True) -> None:
        spec = {
            **self.spec, "seccomp_fd": self.seccomp_fd,
            "services": [listener.service for listener in self.listeners],
            "rlimits": [[limit, *values] for limit, values in self.rlimits.items()],
        }  # fmt: skip
        self._close(*self.pass_fds())
        try:
            sockets = await asyncio.to_thread(self._handshake, spec)
            self._adopt_init(first_child(launcher_pid))
            self.pidns = os.stat(f"/proc/{self.init_pid}/ns/pid").st_ino
            await self._enter_cgroup(wait_for_cgroup)
            await self._serve(sockets)
            if self.in_force.network == "full":
                await self._open_nat()
        except BaseException:
            self.control.close()
            raise

    async def _open_nat(self) -> None:
        """slirp4netns, as the agent's own account, enters the run's user namespace (the
        agent made it: its owner may) to make the tap device; `ip` is run there the same way
        (nsenter) to set it up and refuse the private ranges. The run's resolv.conf came
        with the box's spec (InForce.inbox_spec)."""
        userns = f"/proc/{self.init_pid}/ns/user"
        await self._start_nat(f"--userns-path={userns}")
        ranges = blocked_ranges(self.in_force.policy.allow_networks, host_addresses())
        enter = [tool("nsenter"), f"--target={self.init_pid}", "--user", "--net",
                 "--preserve-credentials", "--"]  # fmt: skip
        await asyncio.to_thread(netns.configure_nat, tool("ip"), ranges, enter)

    async def go(self, launch: Launch, gate=None) -> None:
        try:
            await _pass(gate)
            run = {
                "filename": launch.filename, "argv": launch.argv, "env": launch.env,
                "source": base64.b64encode(launch.source).decode(),
            }  # fmt: skip
            try:
                self.control.sendall(json.dumps({"go": run}).encode() + b"\n")
            except OSError:
                raise BoxFailed("the box ended before its program could start") from None
        finally:
            self.control.close()

    def _handshake(self, spec: dict) -> list[socket.socket]:
        self.control.settimeout(INBOX_TIMEOUT)
        self.control.sendall(json.dumps(spec).encode() + b"\n")
        size = len(self.listeners) * 4
        try:
            message, ancillary, _, _ = self.control.recvmsg(64, socket.CMSG_SPACE(size))
        except TimeoutError:
            raise BoxFailed("the run's box did not get ready in time") from None
        if message != b"ready\n":
            raise BoxFailed("the run's box could not be made (see the log)")
        fds = [
            int.from_bytes(data[i : i + 4], sys.byteorder)
            for level, kind, data in ancillary
            if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS
            for i in range(0, len(data) - len(data) % 4, 4)
        ]
        sockets = [socket.socket(fileno=fd) for fd in fds]
        for sock in sockets:
            sock.setblocking(False)
        return sockets


def first_child(pid: int) -> int:
    """unshare --fork's one child: the first process of the run's pid namespace."""
    deadline = time.monotonic() + INBOX_TIMEOUT
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError):
            children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
            if children:
                return int(children[0])
        time.sleep(0.001)
    raise BoxFailed("the run's box did not start")


def make_box(in_force: InForce, **options) -> Box:
    """The box a run gets here: made by bubblewrap and the agent as root, else from inside."""
    return (RootlessBox if in_force.rootless else BwrapBox)(in_force, **options)
