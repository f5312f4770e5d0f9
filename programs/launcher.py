"""The launcher: the paper's "wrapper script", as a command line built for each run.

A run is started as ``setpriv --pdeathsig KILL -- prlimit <limits> -- <interpreter> <file>``:
both are util-linux tools that set their part and exec the next, so the program keeps one
process id, the limits are applied before any of its code runs, and it is killed if its agent
dies. The supervisor adds a new session (own process group), the run's working directory and
a clean environment built here.
"""

import shutil
from dataclasses import dataclass
from pathlib import Path

from programs.languages import SYSTEM_PATH, Language

MB = 1024 * 1024


class LauncherUnavailable(RuntimeError):
    pass


@dataclass(frozen=True)
class Limits:
    cpu_seconds: int = 600
    memory_mb: int = 1024
    processes: int = 64
    open_files: int = 256
    file_size_mb: int = 64

    @classmethod
    def from_settings(cls, values: dict) -> "Limits":
        names = cls.__dataclass_fields__
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


def command(language: Language, program_file: Path, limits: Limits, args=()) -> list[str]:
    return [
        _tool("setpriv"), "--pdeathsig", "KILL", "--",
        _tool("prlimit"), *limits.prlimit_args(), "--",
        *language.command(str(program_file)), *map(str, args),
    ]  # fmt: skip


def environment(language: Language, workdir: Path, extra: dict[str, str]) -> dict[str, str]:
    """A clean environment: nothing of the server's, only what a program needs."""
    env = {
        "PATH": SYSTEM_PATH,
        "HOME": str(workdir),
        "TMPDIR": str(workdir),
        "LANG": "C.UTF-8",
        "LC_ALL": "C.UTF-8",
        "TERM": "dumb",
        **language.env,
        **extra,
    }
    for var, folder in language.client_env().items():
        env[var] = f"{folder}:{env[var]}" if env.get(var) else folder
    return env
