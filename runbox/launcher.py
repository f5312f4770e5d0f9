"""The launcher: the paper's "wrapper script", as a command line built for each run.

A run is started as ``bwrap <box> -- sh`` (its box, made ahead, see runbox.box), then the
shell execs ``setpriv <run's account> -- <interpreter> <file>``: each tool sets its part and
execs the next, so the box, the account and the limits are in place before any of the
program's code runs (see runbox.isolation and runbox.box). The supervisor adds a new session
and the clean environment built here, and enforces what the kernel does not: wall-clock time
and output size.
"""

import resource
import shutil
from dataclasses import dataclass, fields
from pathlib import Path

from runbox import SYSTEM_PATH

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
    cpu_percent: int = 100  # of one CPU, for the whole run (its cgroup); 0: no cap
    output_kb_per_second: int = 256  # its output read at most so fast (supervisor); 0: no cap

    @classmethod
    def from_settings(cls, values: dict) -> "Limits":
        names = {f.name for f in fields(cls)}
        return cls(**{k: int(v) for k, v in values.items() if k in names})

    def rlimits(self, address_space: bool = True) -> dict[int, tuple[int, int]]:
        """Each process's own limits: the backstop of a run's cgroup, or all there is without
        one. CPU: SIGXCPU at the soft limit (reported as such), SIGKILL two seconds later.
        Address space only without a cgroup's memory limit: it counts what a runtime merely
        reserves (node, the JVM)."""
        limits = {
            resource.RLIMIT_CPU: (self.cpu_seconds, self.cpu_seconds + 2),
            resource.RLIMIT_NPROC: (self.processes, self.processes),
            resource.RLIMIT_NOFILE: (self.open_files, self.open_files),
            resource.RLIMIT_FSIZE: (self.file_size_mb * MB, self.file_size_mb * MB),
            resource.RLIMIT_CORE: (0, 0),
        }
        if address_space:
            limits[resource.RLIMIT_AS] = (self.memory_mb * MB, self.memory_mb * MB)
        return limits

    def prlimit_args(self) -> list[str]:
        names = {resource.RLIMIT_CPU: "cpu", resource.RLIMIT_NPROC: "nproc",
                 resource.RLIMIT_NOFILE: "nofile", resource.RLIMIT_FSIZE: "fsize",
                 resource.RLIMIT_CORE: "core", resource.RLIMIT_AS: "as"}  # fmt: skip
        return [f"--{names[r]}={soft}:{hard}" for r, (soft, hard) in self.rlimits().items()]


def _tool(name: str) -> str:
    path = shutil.which(name, path=SYSTEM_PATH)
    if path is None:
        raise LauncherUnavailable(f"{name} (util-linux) is needed to launch programs")
    return path


def command(language, program_file: Path, limits: Limits, args=()) -> list[str]:
    """A program's command line outside a box (the supervisor's own tests): setpriv and
    prlimit set its limits. A boxed run's is InForce.program_command, run by its box."""
    argv = [*language.command(str(program_file)), *map(str, args)]
    prlimit = [_tool("prlimit"), *limits.prlimit_args(), "--"]
    return [_tool("setpriv"), "--pdeathsig", "KILL", "--", *prlimit, *argv]


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
