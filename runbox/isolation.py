"""The run box: how a run is kept apart from the server, the other runs and the network.

Every run starts in bubblewrap with namespaces of its own: pid, ipc, uts, mount and network,
whatever the robot's settings. It sees the language runtimes (/usr, /etc) read-only, the
Robot API clients, the API's socket and its own folder, which is a tmpfs of ``disk_mb`` (the
kernel counts every byte, unlinked files too), and a private /tmp; nothing of the data
folder. Its processes run under an OS account of their own (as root: a numeric id derived
from the run's id; rootless: an id of its own inside a user namespace).

The network a robot's settings choose (``network``):

    none      only the Robot API's Unix socket
    loopback  127.0.0.1 inside the run's own namespace, offering what its robot gives
              programs (the Robot API over TCP, a MAVLink robot's programs endpoint, ports
              the robot names in ``loopback_ports``) through sockets the agent owns
    full      that, and the internet through a user-mode NAT (slirp4netns, whose DNS
              forwarder is the run's resolver), without the private ranges unless
              ``allow_networks`` lists some, and never the host's loopback or addresses

bwrap reports the sandbox's first process on ``--info-fd`` and waits on ``--block-fd``
before it runs anything of the program's, so the agent can put the run in its cgroup and
open its sockets first (see runbox.box). What a robot asks for and cannot be had refuses the
run with a message saying what to install; nothing falls back to running unboxed.
"""

import os
import shutil
import subprocess
import zlib
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

from runbox import SYSTEM_PATH, seccomp
from runbox.cgroups import CgroupSupport
from runbox.netns import NAT_RESOLV_CONF

if TYPE_CHECKING:
    from runbox.launcher import Limits

ISOLATIONS = ("auto", "sandbox")
NETWORKS = ("none", "loopback", "full")
UID_BASE = 1_000_000_000
SLOTS, RUNS_PER_SLOT = 1000, 1_000_000
# The id a rootless run has inside its user namespace (the agent's own outside).
ROOTLESS_UID = 1000
TOPS = ("bin", "sbin", "lib", "lib32", "lib64", "libx32")  # besides /usr, maybe links into it
INBOX = Path(__file__).resolve().parent / "inbox.py"
SYSTEM_PYTHON = "/usr/bin/python3"  # runs the rootless box's first process
# The server's tools may live in sbin; programs' PATH (SYSTEM_PATH) has no need of it.
TOOLS_PATH = f"/usr/local/sbin:/usr/sbin:/sbin:{SYSTEM_PATH}"
TUN = "/dev/net/tun"  # slirp4netns's tap device, opened by an agent that is not root


class IsolationUnavailable(RuntimeError):
    """The isolation a robot asks for cannot be had here: the run is refused."""


@dataclass(frozen=True)
class Policy:
    isolation: str = "auto"
    network: str = "loopback"
    tmp_mb: int = 64
    loopback_ports: tuple[str, ...] = ()  # "tcp:9090", "udp:5600": host services relayed in
    allow_networks: tuple[str, ...] = ()  # private ranges a `full` run may reach

    @classmethod
    def from_settings(cls, settings: dict) -> "Policy":
        from runbox.netspec import parse_networks, parse_ports

        isolation = str(settings.get("isolation", cls.isolation))
        if isolation == "account":  # a setting of old: runs without a box are no more
            raise IsolationUnavailable(
                "isolation 'account' (no sandbox) is no longer offered: every run is boxed;"
                " set isolation to 'auto'"
            )
        if isolation not in ISOLATIONS:
            raise IsolationUnavailable(
                f"unknown isolation {isolation!r}; choose one of {', '.join(ISOLATIONS)}"
            )
        network = str(settings.get("network", cls.network))
        if network not in NETWORKS:
            raise IsolationUnavailable(
                f"unknown network {network!r}; choose one of {', '.join(NETWORKS)}"
            )
        try:
            ports = parse_ports(settings.get("loopback_ports", ()))
            allowed = parse_networks(settings.get("allow_networks", ()))
        except ValueError as exc:
            raise IsolationUnavailable(str(exc)) from None
        return cls(isolation, network, int(settings.get("tmp_mb", cls.tmp_mb)), ports, allowed)

    def resolve(self, clients_dir: Path, cgroups: CgroupSupport | None = None) -> "InForce":
        """What this machine gives for the policy, or IsolationUnavailable saying why not;
        `cgroups`: what runs' cgroups are made with here (runbox.share.runs_cgroups), if any."""
        if not seccomp.available():
            raise IsolationUnavailable(
                "runs get a seccomp filter, and libseccomp cannot make one here"
                " (apt-get install libseccomp2)"
            )
        rootless = os.geteuid() != 0
        if rootless:
            return self._resolve_rootless(clients_dir, cgroups)
        if bwrap_path() is None:
            raise IsolationUnavailable(
                "runs are boxed with bubblewrap, which is not installed"
                " (apt-get install bubblewrap)"
            )
        if self.network == "full":
            _full_network_needs(("slirp4netns", "slirp4netns"), ("ip", "iproute2"))
        return InForce(self, clients_dir, rootless, cgroups)

    def _resolve_rootless(self, clients_dir: Path, cgroups: CgroupSupport | None) -> "InForce":
        if self.network == "full":
            _full_network_needs(
                ("slirp4netns", "slirp4netns"), ("ip", "iproute2"), ("nsenter", "util-linux")
            )
            if not os.access(TUN, os.R_OK | os.W_OK):
                raise IsolationUnavailable(
                    f"network 'full' as an ordinary user needs {TUN} open to it (Debian's"
                    " default: mode 0666); or run robotide as root, or choose 'loopback'"
                )
        if not os.path.exists(SYSTEM_PYTHON) or shutil.which("unshare", path=TOOLS_PATH) is None:
            raise IsolationUnavailable(f"rootless runs need {SYSTEM_PYTHON} and util-linux")
        if not user_namespaces_allowed():
            raise IsolationUnavailable(
                "rootless runs need unprivileged user namespaces, which this kernel refuses"
                " (sysctl kernel.unprivileged_userns_clone=1), or run robotide as root"
            )
        return InForce(self, clients_dir, rootless=True, cgroups=cgroups)


@dataclass(frozen=True)
class InForce:
    policy: Policy
    clients_dir: Path  # the Robot API clients, mounted read-only for the run
    rootless: bool = False
    # The cgroups each run and all runs together get (None: not looked at, as none).
    cgroups: CgroupSupport | None = None

    @property
    def network(self) -> str:
        return self.policy.network

    @property
    def run_wide(self) -> bool:
        """Whether a cgroup bounds each run as a whole (memory, processes across its forks)."""
        return self.cgroups is not None and self.cgroups.available

    @property
    def runs_at_once(self) -> int | None:
        """How many runs of one robot may run together: without a run-wide cgroup one run's
        processes are bounded each on its own, and a second run would double what the robot's
        runs may take; None: as many as the queue allows."""
        return None if self.run_wide else 1

    def describe(self, limits: "Limits | None" = None) -> str:
        """What is in force, in words the robot page shows (robots.isolation_words translates
        them): never a limit that does not exist. `limits`: the robot's runs' (launcher)."""
        account = "own user namespace" if self.rootless else "own OS account"
        box = "rootless box (user namespaces)" if self.rootless else "sandbox (bubblewrap)"
        parts = [f"{box}, {account}, seccomp, network {self.network}"]
        if self.cgroups is not None:
            parts.append(self.cgroups.describe())  # "no cgroups: <why> — per-process rlimits only"
        if not self.run_wide:
            bound = self._per_process(limits)
            if self.cgroups is None:
                parts.append(f"per-process rlimits only: {bound}")
            else:
                parts[-1] += f": {bound}"
            unbounded = "no run-wide memory limit"
            parts.append(f"{unbounded}: no delegated cgroup" if self.rootless else unbounded)
        return "; ".join(parts)

    def _per_process(self, limits: "Limits | None") -> str:
        """What bounds a run without a cgroup (launcher.Limits.rlimits, address_space=True)."""
        if limits is None:
            return "one run at a time"
        return (
            f"each process at most {limits.memory_mb} MB, at most {limits.processes}"
            " processes, one run at a time"
        )

    # Where a run sees its folder, the Robot API socket and the clients: fixed places,
    # whatever the host's layout.
    HOME = Path("/home/robot")
    API_DIR = Path("/run/robot")
    CLIENTS = Path("/opt/robotide/clients")

    def home(self) -> Path:
        return self.HOME

    def api_dir(self) -> Path:
        return self.API_DIR

    def clients(self) -> Path:
        return self.CLIENTS

    def uid(self, run_id: int, instance: str) -> int:
        return ROOTLESS_UID if self.rootless else run_uid(run_id, instance)

    def program_command(self, argv: list[str], uid: int) -> list[str]:
        """What the box runs for the program. As root, setpriv drops to the run's account
        first; rootless, the box's first process has made it uid 1000 already."""
        if self.rootless:
            return list(argv)
        account = [
            tool("setpriv"), f"--reuid={uid}", f"--regid={uid}", "--clear-groups",
            "--no-new-privs", "--",
        ]  # fmt: skip
        return [*account, *argv]

    def unshare(self) -> list[str]:
        """Rootless: util-linux makes the namespaces (it is on every Debian machine), the
        system's python3 runs runbox/inbox.py in them; both end with the agent."""
        return [
            tool("setpriv"), "--pdeathsig", "KILL", "--",
            tool("unshare"), "--user", "--map-root-user", "--mount", "--pid", "--fork",
            "--net", "--ipc", "--uts", "--kill-child", "--",
            SYSTEM_PYTHON, "-I", "-S", str(INBOX),
        ]  # fmt: skip

    def inbox_spec(self, socket_dir: Path, disk_mb: int) -> dict:
        readonly = ["/usr", "/etc", *(f"/{top}" for top in TOPS)]
        place = resolv_conf_place() if self.network == "full" else None
        resolv = None
        if place is not None:
            resolv = {"folders": place[0], "path": place[1], "text": NAT_RESOLV_CONF}
        return {
            "resolv_conf": resolv,
            "readonly": readonly, "clients": str(self.clients_dir),
            "clients_at": str(self.CLIENTS), "api_dir": str(socket_dir),
            "api_at": str(self.API_DIR), "home": str(self.HOME),
            "tmp_mb": self.policy.tmp_mb, "disk_mb": disk_mb,
        }  # fmt: skip

    def bwrap(self, socket_dir: Path) -> list[str]:
        args = [
            bwrap_path(), "--die-with-parent", "--unshare-pid", "--unshare-ipc",
            "--unshare-uts", "--unshare-net", "--unshare-cgroup-try", "--hostname", "robot",
            "--ro-bind", "/usr", "/usr", "--ro-bind", "/etc", "/etc",
            "--proc", "/proc", "--dev", "/dev",
            "--perms", "1777", "--size", str(self.policy.tmp_mb * 1024 * 1024), "--tmpfs", "/tmp",
            # POSIX shared memory and semaphores (multiprocessing's): bubblewrap's is root's.
            "--perms", "1777", "--size", str(self.policy.tmp_mb * 1024 * 1024),
            "--tmpfs", "/dev/shm",
            # Mount points' parents: bubblewrap would make them 0700, closed to the run.
            *(arg for d in ("/home", "/run", "/opt", "/opt/robotide")
              for arg in ("--perms", "0755", "--dir", d)),
            "--ro-bind", str(self.clients_dir), str(self.CLIENTS),
            # Read-only: the robot's, shared by its runs (connect() needs no write to it).
            "--ro-bind", str(socket_dir), str(self.API_DIR),
        ]  # fmt: skip
        for top in TOPS:
            path = Path("/") / top
            if path.is_symlink():
                args += ["--symlink", os.readlink(path), str(path)]
            elif path.is_dir():
                args += ["--ro-bind", str(path), str(path)]
        return args

    @staticmethod
    def resolv_conf_args(fd: int) -> list[str]:
        """bubblewrap's arguments for the run's resolv.conf, read from `fd`."""
        place = resolv_conf_place()
        if place is None:
            return []
        folders, path = place
        made = [arg for folder in folders for arg in ("--perms", "0755", "--dir", folder)]
        return [*made, "--perms", "0644", "--ro-bind-data", str(fd), path]

    def folder_args(self, disk_mb: int) -> list[str]:
        """The run's folder: a tmpfs of `disk_mb`, where it starts (the program comes later)."""
        home = str(self.HOME)
        return [
            "--perms", "1777", "--size", str(disk_mb * 1024 * 1024), "--tmpfs", home,
            "--chdir", home,
        ]  # fmt: skip


def run_uid(run_id: int, instance: str) -> int:
    """The run's account id as root. Run ids are unique within one robotide (one database,
    one data folder); another robotide on the same machine gets another slice of the range."""
    slot = zlib.crc32(instance.encode()) % SLOTS
    return UID_BASE + slot * RUNS_PER_SLOT + run_id % RUNS_PER_SLOT


def resolv_conf_place(host_file: str = "/etc/resolv.conf") -> tuple[list[str], str] | None:
    """Where a box's own resolv.conf goes: the box's /etc/resolv.conf itself, or where its
    links lead out of what the box shares with the host (systemd-resolved's link into /run:
    then the folders to make there, open to the run). None where the host has none."""
    path = Path(host_file)
    for _ in range(40):  # as the kernel's limit of links followed
        if path.parts[1] not in ("etc", "usr", *TOPS):
            folders = [str(parent) for parent in reversed(path.parents[:-1])]
            return folders, str(path)
        if not path.is_symlink():
            return ([], str(path)) if path.is_file() else None
        path = Path(os.path.normpath(path.parent / os.readlink(path)))
    return None


def _full_network_needs(*tools: tuple[str, str]) -> None:
    """IsolationUnavailable naming the first of `tools` (name, Debian package) not installed."""
    for name, package in tools:
        if shutil.which(name, path=TOOLS_PATH) is None:
            raise IsolationUnavailable(
                f"network 'full' needs {name} (apt-get install {package});"
                " or choose network 'loopback'"
            )


def tool(name: str) -> str:
    path = shutil.which(name, path=TOOLS_PATH)
    if path is None:
        raise IsolationUnavailable(f"{name} (util-linux) is needed to launch programs")
    return path


@cache
def user_namespaces_allowed() -> bool:
    done = subprocess.run(
        [tool("unshare"), "--user", "--map-root-user", "true"], capture_output=True, timeout=10
    )
    return done.returncode == 0


@cache
def bwrap_path() -> str | None:
    return shutil.which("bwrap", path=TOOLS_PATH)
