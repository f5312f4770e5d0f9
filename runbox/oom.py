"""Whom the kernel's OOM killer picks when memory runs out: a run's process, never the server.

oom_score_adj goes from -1000 (never) to 1000 (first); a child starts with its parent's. The
server and the agents lower their own where they may (root: CAP_SYS_RESOURCE), not to -1000:
a server that leaks must still be stoppable by the kernel rather than take the machine down.
An ordinary user may only raise a value: there the server keeps 0 and the runs go first all
the same, every box being at 1000, its program and forks with it (a rootless box is started
by util-linux choom; a root one is set by the agent before its program starts).
"""

import os
from pathlib import Path

SERVER = -500  # the server and its agents, as root
RUN = 1000  # every process of a run: the OOM killer's first choice
SELF = Path("/proc/self/oom_score_adj")


def protect_this_process() -> int:
    """The server's or an agent's own oom_score_adj lowered to SERVER where the kernel allows
    it (root); returns what is in force."""
    if os.geteuid() == 0:
        try:
            SELF.write_text(f"{SERVER}\n")
        except OSError:  # a container without CAP_SYS_RESOURCE
            pass
    return score_adj()


def score_adj(pid: int | str = "self") -> int:
    return int(Path(f"/proc/{pid}/oom_score_adj").read_text())


def first_to_go(argv: list[str], choom: str) -> list[str]:
    """`argv`, started with the runs' oom_score_adj (`choom`: its path)."""
    return [choom, "-n", str(RUN), "--", *argv]


def first_to_go_now(pid: int) -> None:
    """Process `pid` (of a box not yet running anything of its program's) at the runs'
    oom_score_adj: as root, with no exec of choom on a run's way."""
    Path(f"/proc/{pid}/oom_score_adj").write_text(f"{RUN}\n")
