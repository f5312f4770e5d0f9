"""The launcher: the paper's "wrapper script", as a command line built for each run.

A run is started as ``bwrap <box> -- setpriv <run's account> -- prlimit <limits> --
<interpreter> <file>``: each tool sets its part and execs the next, so the box, the account
and the limits are in place before any of the program's code runs (see runbox.isolation and
runbox.box). The supervisor adds a new session and the clean environment built here, and
enforces what the kernel does not: wall-clock time and output size.
"""

import shutil
from dataclasses import dataclass, fields
from pathlib import Path

from runbox import SYSTEM_PATH
from runbox.isolation import InForce

MB = 1024 * 1024


class LauncherUnavailable(RuntimeError):
    pass


@dataclass(frozen=True)
class Limits:
    cpu_seconds: int = 600
    wall_seconds: int = 0  # 0: no limit (a robot's program may run all day)
    memory_mb: int = 1024
    processes: int = 64
    open_files: int = 256
    file_size_mb: int = 64
    disk_mb: int = 256
    log_size_mb: int = 64

    @classmethod
    def from_settings(cls, values: dict) -> "Limits":
        names = {f.name for f in fields(cls)}
        return cls(**{k: int(v) for k, v in values.items() if k in names})

    def prlimit_args(self) -> list[str]:
        # CPU: SIGXCPU at the soft limit (reported as such), SIGKILL two seconds later.
        return [
            f"--cpu={self.cpu_seconds}:{self.cpu_seconds + 2}",
            f"--as={self.memory_mb * MB}",
            f"--nproc={self.processes}",
            f"--nofile={self.open_files}",
            f"--fsize={self.file_size_mb * MB}",
            "--core=0",
        ]


def _tool(name: str) -> str:
    path = shutil.which(name, path=SYSTEM_PATH)
    if path is None:
        raise LauncherUnavailable(f"{name} (util-linux) is needed to launch programs")
    return path


def command(
    language,
    program_file: Path,
    limits: Limits,
    args=(),
    isolation: InForce | None = None,
    uid: int | None = None,
    socket_dir: Path | None = None,
    box_args: list[str] = (),
) -> list[str]:
    """The run's command line; without `isolation` (tests of the supervisor) it stays as is.
    In a box, `program_file` is where the program lies inside it."""
    argv = [
        _tool("prlimit"), *limits.prlimit_args(), "--",
        *language.command(str(program_file)), *map(str, args),
    ]  # fmt: skip
    if isolation is None:
        return [_tool("setpriv"), "--pdeathsig", "KILL", "--", *argv]
    return isolation.wrap(argv, uid, socket_dir, list(box_args))


def environment(
    language, home: Path, extra: dict[str, str], clients_dir: Path | None = None
) -> dict[str, str]:
    """A clean environment: nothing of the server's, only what a program needs."""
    env = {
        "PATH": SYSTEM_PATH,
        "HOME": str(home),
        "TMPDIR": str(home),
        "LANG": "C.UTF-8",
        "LC_ALL": "C.UTF-8",
        "TERM": "dumb",
        **language.env,
        **extra,
    }
    clients = language.client_env(clients_dir) if clients_dir else language.client_env()
    for var, folder in clients.items():
        env[var] = f"{folder}:{env[var]}" if env.get(var) else folder
    return env
