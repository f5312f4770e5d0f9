"""How a robot's programs are boxed, in the reader's language: runbox describes it in English
(it has no Django) and Robot.isolation keeps that text, which the API gives as it is."""

import re

from django.utils.translation import gettext_lazy as _

WORDS = {
    "sandbox (bubblewrap)": _("sandbox (bubblewrap)"),
    "rootless box (user namespaces)": _("rootless box (user namespaces)"),
    "own OS account": _("own OS account"),
    "own user namespace": _("own user namespace"),
    "network": _("network"),
    "no cgroups": _("no cgroups"),
    "per-process rlimits only": _("per-process rlimits only"),
    "memory+swap": _("memory+swap"),
    "memory": _("memory"),
    "pids": _("pids"),  # the controller: processes
    # runbox.share: all runs' parent cgroup
    "all runs together at most": _("all runs together at most"),
    "MB of memory and": _("MB of memory and"),
    "CPU weight": _("CPU weight"),
    "the server's": _("the server's"),
    # runbox.isolation: a run bounded without a run-wide cgroup
    "each process at most": _("each process at most"),
    "at most": _("at most"),
    "processes": _("processes"),
    "one run at a time": _("one run at a time"),
    "no run-wide memory limit": _("no run-wide memory limit"),
    "no delegated cgroup": _("no delegated cgroup"),
}
# Longest first, whole words only: "memory+swap" before "memory".
_FRAGMENT = re.compile(
    "|".join(rf"(?<![\w+]){re.escape(w)}(?![\w+])" for w in sorted(WORDS, key=len, reverse=True))
)


def isolation_shown(text: str) -> str:
    return _FRAGMENT.sub(lambda found: str(WORDS[found.group(0)]), text)
