"""How a run is kept apart from the server, the other runs and the network.

Every run gets an OS account of its own: a numeric user and group id, never the server's,
derived from the run's id and its robotide's data folder. Where bubblewrap is
installed the run also sees only its own filesystem: the language runtimes (/usr, /etc), the
Robot API clients and socket, its working directory and a private /tmp; nothing of the data
directory. The network a run may use is part of its id range, so one static nftables table
serves every robot:

    1_000_000_000 + n   network "none"      everything refused (Unix sockets still work)
    1_100_000_000 + n   network "loopback"  only the loopback interface
    1_200_000_000 + n   network "full"

A robot's settings choose ``isolation`` (``auto``, ``sandbox``, ``account``) and ``network``
(``none``, ``loopback``, ``full``). What they ask for and cannot be had refuses the run with a
message saying what to install or change; nothing falls back to running unconfined.
"""

import os
import shutil
import subprocess
import zlib
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from runbox import SYSTEM_PATH

ISOLATIONS = ("auto", "sandbox", "account")
NETWORKS = ("none", "loopback", "full")
UID_BASE = {"none": 1_000_000_000, "loopback": 1_100_000_000, "full": 1_200_000_000}
UIDS_PER_NETWORK = 100_000_000
SLOTS, RUNS_PER_SLOT = 1000, 100_000
NFT_TABLE = "robotide"
# The server's tools may live in sbin; programs' PATH (SYSTEM_PATH) has no need of it.
TOOLS_PATH = f"/usr/local/sbin:/usr/sbin:/sbin:{SYSTEM_PATH}"


class IsolationUnavailable(RuntimeError):
    """The isolation a robot asks for cannot be had here: the run is refused."""


@dataclass(frozen=True)
class Policy:
    isolation: str = "auto"
    network: str = "loopback"
    tmp_mb: int = 64

    @classmethod
    def from_settings(cls, settings: dict) -> "Policy":
        policy = cls(
            isolation=str(settings.get("isolation", cls.isolation)),
            network=str(settings.get("network", cls.network)),
            tmp_mb=int(settings.get("tmp_mb", cls.tmp_mb)),
        )
        if policy.isolation not in ISOLATIONS:
            raise IsolationUnavailable(
                f"unknown isolation {policy.isolation!r}; choose one of {', '.join(ISOLATIONS)}"
            )
        if policy.network not in NETWORKS:
            raise IsolationUnavailable(
                f"unknown network {policy.network!r}; choose one of {', '.join(NETWORKS)}"
            )
        return policy

    def resolve(self, clients_dir: Path) -> "InForce":
        """What this machine gives for the policy, or IsolationUnavailable saying why not."""
        if not can_switch_user():
            raise IsolationUnavailable(
                "runs need an OS account of their own, and this server cannot switch accounts:"
                " run robotide as root (or with CAP_SETUID and CAP_SETGID)"
            )
        sandbox = self.isolation in ("auto", "sandbox") and bwrap_path() is not None
        if self.isolation == "sandbox" and not sandbox:
            raise IsolationUnavailable(
                "this robot asks for a sandbox and bubblewrap is not installed"
                " (apt-get install bubblewrap), or set its isolation to 'account'"
            )
        firewall_needed = self.network == "loopback" or (self.network == "none" and not sandbox)
        if firewall_needed and not firewall_ready():
            raise IsolationUnavailable(
                f"network {self.network!r} needs nftables and CAP_NET_ADMIN"
                " (apt-get install nftables; run robotide as root); or choose another network"
            )
        return InForce(sandbox, self.network, self.tmp_mb, clients_dir)


@dataclass(frozen=True)
class InForce:
    sandbox: bool
    network: str
    tmp_mb: int
    clients_dir: Path  # the Robot API clients, mounted read-only for the run

    def describe(self) -> str:
        where = "sandbox (bubblewrap)" if self.sandbox else "own account, shared filesystem"
        return f"{where}, own OS account, network {self.network}"

    # Where a sandboxed run sees its folder, the Robot API socket and the clients: fixed
    # places, whatever the host's layout (and whoever may pass through its folders).
    HOME = Path("/home/robot")
    API_DIR = Path("/run/robot")
    CLIENTS = Path("/opt/robotide/clients")

    def home(self, workdir: Path) -> Path:
        return self.HOME if self.sandbox else workdir

    def api_dir(self, socket_dir: Path) -> Path:
        return self.API_DIR if self.sandbox else socket_dir

    def clients(self) -> Path:
        return self.CLIENTS if self.sandbox else self.clients_dir

    def uid(self, run_id: int, instance: str) -> int:
        return run_uid(self.network, run_id, instance)

    def wrap(self, argv: list[str], uid: int, workdir: Path, socket_dir: Path) -> list[str]:
        """The command with its account switch and, if any, its sandbox around it.

        bubblewrap runs first, as the server's account, so it can mount what the run may see
        wherever it lies; setpriv inside then drops to the run's account for good.
        """
        account = [
            tool("setpriv"), f"--reuid={uid}", f"--regid={uid}", "--clear-groups",
            "--no-new-privs", "--pdeathsig", "KILL", "--",
        ]  # fmt: skip
        if not self.sandbox:
            return [*account, *argv]
        return [*self.bwrap(workdir, socket_dir), "--", *account, *argv]

    def bwrap(self, workdir: Path, socket_dir: Path) -> list[str]:
        args = [
            bwrap_path(), "--die-with-parent", "--unshare-pid", "--unshare-ipc",
            "--unshare-uts", "--unshare-cgroup-try", "--hostname", "robot",
            "--ro-bind", "/usr", "/usr", "--ro-bind", "/etc", "/etc",
            "--proc", "/proc", "--dev", "/dev",
            "--perms", "1777", "--size", str(self.tmp_mb * 1024 * 1024), "--tmpfs", "/tmp",
            # Mount points' parents: bubblewrap would make them 0700, closed to the run.
            *(arg for d in ("/home", "/run", "/opt", "/opt/robotide")
              for arg in ("--perms", "0755", "--dir", d)),
            "--ro-bind", str(self.clients_dir), str(self.CLIENTS),
            "--bind", str(socket_dir), str(self.API_DIR),
            "--bind", str(workdir), str(self.HOME), "--chdir", str(self.HOME),
        ]  # fmt: skip
        for top in ("bin", "sbin", "lib", "lib32", "lib64", "libx32"):
            path = Path("/") / top
            if path.is_symlink():
                args += ["--symlink", os.readlink(path), str(path)]
            elif path.is_dir():
                args += ["--ro-bind", str(path), str(path)]
        if self.network == "none":
            args.append("--unshare-net")
        return args


def run_uid(network: str, run_id: int, instance: str) -> int:
    """The run's account id. Run ids are unique within one robotide (one database, one data
    folder); another robotide on the same machine gets another slice of the range."""
    slot = zlib.crc32(instance.encode()) % SLOTS
    return UID_BASE[network] + slot * RUNS_PER_SLOT + run_id % RUNS_PER_SLOT


def tool(name: str) -> str:
    path = shutil.which(name, path=TOOLS_PATH)
    if path is None:
        raise IsolationUnavailable(f"{name} (util-linux) is needed to launch programs")
    return path


@cache
def bwrap_path() -> str | None:
    return shutil.which("bwrap", path=TOOLS_PATH)


def can_switch_user() -> bool:
    return os.geteuid() == 0


@cache
def firewall_ready() -> bool:
    """Install the nftables table that keeps each id range to its network (idempotent)."""
    nft = shutil.which("nft", path=TOOLS_PATH)
    if nft is None or os.geteuid() != 0:
        return False
    none, loopback = UID_BASE["none"], UID_BASE["loopback"]
    ruleset = f"""
table inet {NFT_TABLE}
delete table inet {NFT_TABLE}
table inet {NFT_TABLE} {{
    chain output {{
        type filter hook output priority 0; policy accept;
        meta skuid {none}-{none + UIDS_PER_NETWORK - 1} reject
        meta skuid {loopback}-{loopback + UIDS_PER_NETWORK - 1} oifname != "lo" reject
    }}
}}
"""
    done = subprocess.run([nft, "-f", "-"], input=ruleset, text=True, capture_output=True)
    return done.returncode == 0


def prepare_workdir(workdir: Path, uid: int) -> None:
    """The run's own folder, which only its account may enter."""
    workdir.mkdir(parents=True, exist_ok=True)
    workdir.parent.chmod(0o711)  # the run's folder: its log stays the server's (0600)
    for entry in [workdir, *workdir.rglob("*")]:
        os.chown(entry, uid, uid, follow_symlinks=False)
    workdir.chmod(0o700)


def unreachable_ancestor(path: Path) -> Path | None:
    """The first folder above `path` that other accounts cannot pass through, if any.

    Without a sandbox a run's account reaches its folder through the real path.
    """
    for parent in reversed(path.parents):
        if not parent.stat().st_mode & 0o001:
            return parent
    return None
