"""How a robot's programs are boxed, in the reader's language.

runbox describes it in English (it has no Django) and Robot.isolation keeps that text, which
the API gives as it is. Here the text is read back into its parts (runbox's few fixed phrases:
runbox.isolation.InForce.describe, runbox.cgroups.CgroupSupport.describe and its reasons,
runbox.share.RunsParent.describe) and each part is said again through gettext with
placeholders: paths, cgroup names and numbers go in as they are, never a word of them
translated. A text that is no such line (why runs cannot start here, a new phrase of runbox's)
is shown as it is, in English, rather than half translated.
"""

import re

from django.utils.translation import gettext as _
from django.utils.translation import pgettext


def _phrases() -> dict[str, str]:
    """The fixed words of the line's head, each in the reader's language (read at each call:
    the language is the request's)."""
    return {
        "sandbox (bubblewrap)": _("in a sandbox (bubblewrap)"),
        "rootless box (user namespaces)": _("in a rootless box (user namespaces)"),
        "own OS account": _("each under its own OS account"),
        "own user namespace": _("each in its own user namespace"),
        "none": _("no network"),
        "loopback": _("network on loopback only"),
        "full": _("full network"),
    }


def _controllers() -> dict[str, str]:
    return {
        "memory": pgettext("cgroup controller", "memory"),
        "memory+swap": pgettext("cgroup controller", "memory+swap"),
        "pids": pgettext("cgroup controller", "processes"),
        "cpu": pgettext("cgroup controller", "CPU"),
        "cpuacct": pgettext("cgroup controller", "CPU accounting"),
        "freezer": pgettext("cgroup controller", "freezing"),
        "kill": pgettext("cgroup controller", "ending all at once"),
    }


HEAD = re.compile(
    r"(?P<box>sandbox \(bubblewrap\)|rootless box \(user namespaces\)),"
    r" (?P<account>own OS account|own user namespace), seccomp, network (?P<network>\w+)"
)
CGROUP = re.compile(r"cgroup (?P<version>v[12]) \((?P<controllers>[^()]*)\)")
PARENT = re.compile(
    r"all runs together at most (?P<memory>\d+) MB of memory and (?P<pids>\d+) processes,"
    r" CPU weight (?P<weight>\d+) \(the server's (?P<server>\d+)\)"
)
NO_CGROUPS = re.compile(r"no cgroups: (?P<why>.+) — per-process rlimits only(?:: (?P<bound>.+))?")
RLIMITS = re.compile(r"per-process rlimits only: (?P<bound>.+)")
UNBOUNDED = re.compile(r"no run-wide memory limit(?P<undelegated>: no delegated cgroup)?")
EACH = re.compile(
    r"each process at most (?P<memory>\d+) MB, at most (?P<processes>\d+) processes,"
    r" one run at a time"
)

# Why a machine gives no cgroups (runbox.cgroups, runbox.share): a pattern, what it says.
WHY = [
    (r"cannot read (?P<file>\S+): (?P<error>.+)", lambda: _("cannot read %(file)s: %(error)s")),
    (
        r"no memory cgroup controller is mounted",
        lambda: _("no memory cgroup controller is mounted"),
    ),
    (
        r"robotide is not root and cannot write to (?P<path>\S+)"
        r" \(run it in a systemd unit with Delegate=yes\)",
        lambda: _(
            "robotide is not root and cannot write to %(path)s (run it in a systemd unit"
            " with Delegate=yes)"
        ),
    ),
    (
        r"robotide is not root and cannot write to (?P<path>\S+)",
        lambda: _("robotide is not root and cannot write to %(path)s"),
    ),
    (r"(?P<path>/\S*) is read-only", lambda: _("%(path)s is read-only")),
    (
        r"the memory cgroup \(v1\) is not mounted where it is seen",
        lambda: _("the memory cgroup (v1) is not mounted where robotide sees it"),
    ),
    (
        r"the cgroup v2 tree does not show this process's (?P<path>\S+)",
        lambda: _("the cgroup v2 tree does not show robotide's own cgroup %(path)s"),
    ),
    (
        r"the memory controller is not delegated to (?P<path>\S+) \(cgroup v2\)",
        lambda: _("the memory controller is not delegated to %(path)s (cgroup v2)"),
    ),
    (
        r"the runs' parent cgroup (?P<name>\S+) could not be made: (?P<error>.+)",
        lambda: _("the runs' parent cgroup %(name)s could not be made: %(error)s"),
    ),
]


class Unknown(ValueError):
    """A text that is not runbox's description of a box."""


def parts(text: str) -> list[tuple[str, dict]]:
    """The line as (kind, values) parts; Unknown if any part is not one runbox writes."""
    pieces = text.split("; ")
    found = []
    head = HEAD.fullmatch(pieces[0])
    if head is None:
        raise Unknown(text)
    found.append(("head", head.groupdict()))
    for piece in pieces[1:]:
        for kind, pattern in (
            ("cgroup", CGROUP), ("parent", PARENT), ("no_cgroups", NO_CGROUPS),
            ("rlimits", RLIMITS), ("unbounded", UNBOUNDED),
        ):  # fmt: skip
            if match := pattern.fullmatch(piece):
                found.append((kind, match.groupdict()))
                break
        else:
            raise Unknown(text)
    return found


def is_box(text: str) -> bool:
    """Whether the text says how runs are boxed (not why they cannot run)."""
    try:
        parts(text)
    except Unknown:
        return False
    return True


def isolation_shown(text: str) -> str:
    """runbox's line in the reader's language; a text not runbox's line as it is."""
    try:
        found = parts(text)
    except Unknown:
        return text
    return "; ".join(_say(kind, values) for kind, values in found)


def _say(kind: str, values: dict) -> str:
    if kind == "head":
        phrases = _phrases()
        network = phrases.get(values["network"]) or _("network %(kind)s") % {
            "kind": values["network"]
        }
        return _("%(box)s, %(account)s, seccomp, %(network)s") % {
            "box": phrases[values["box"]], "account": phrases[values["account"]],
            "network": network,
        }  # fmt: skip
    if kind == "cgroup":
        names = _controllers()
        shown = [names.get(name, name) for name in values["controllers"].split(", ")]
        return _("cgroup %(version)s (%(controllers)s)") % {
            "version": values["version"], "controllers": ", ".join(shown),
        }  # fmt: skip
    if kind == "parent":
        return (
            _(
                "all runs together at most %(memory)s MB of memory and %(pids)s processes,"
                " CPU weight %(weight)s (the server's: %(server)s)"
            )
            % values
        )
    if kind == "no_cgroups":
        said = _("no cgroups: %(why)s — per-process rlimits only") % {"why": _why(values["why"])}
        return f"{said}: {_bound(values['bound'])}" if values["bound"] else said
    if kind == "rlimits":
        return _("per-process rlimits only: %(bound)s") % {"bound": _bound(values["bound"])}
    if values["undelegated"]:
        return _("no run-wide memory limit: no delegated cgroup")
    return _("no run-wide memory limit")


def _bound(text: str) -> str:
    if text == "one run at a time":
        return _("one run at a time")
    if match := EACH.fullmatch(text):
        return (
            _(
                "each process at most %(memory)s MB, at most %(processes)s processes,"
                " one run at a time"
            )
            % match.groupdict()
        )
    return text


def _why(text: str) -> str:
    for pattern, said in WHY:
        if match := re.fullmatch(pattern, text):
            return said() % match.groupdict()
    return text
