"""The static checks of a blocks program: which blocks it uses, how many (no Django).

A blocks program's source is Blockly's JSON serialization of the workspace (programs.blocks
describes it). The blocks counted are the ones that run: the top blocks of each stack, what
follows them (``next``) and what is plugged into their inputs (``block``), not shadows (the
default values an input shows) and not disabled blocks with what is inside them (Blockly makes
no code of those, and neither does programs.blocks).
"""

from __future__ import annotations

import json
from collections.abc import Callable

MAX_BLOCKS = 100_000
LOOPS = (
    "controls_repeat_ext", "controls_repeat", "controls_whileUntil", "controls_for",
    "controls_forEach",
)  # fmt: skip
CONDITIONS = ("controls_if", "controls_ifelse", "logic_ternary")
GROUPS = {"loop": LOOPS, "condition": CONDITIONS}
LANGUAGE_NAMES = {
    "python": "Python", "javascript": "JavaScript", "ruby": "Ruby", "perl": "Perl",
    "lua": "Lua", "tcl": "Tcl", "shell": "shell", "blocks": "blocks",
}  # fmt: skip


def _same(text: str) -> str:
    return text


def language_name(language: str) -> str:
    return LANGUAGE_NAMES.get(language, language)


def blocks_of(source: str) -> list[dict]:
    """Every block of the program that runs (see the module's docstring); ValueError for a
    source that is not a blocks workspace."""
    try:
        workspace = json.loads(source)
    except (ValueError, RecursionError):
        raise ValueError("not JSON") from None
    if not isinstance(workspace, dict):
        raise ValueError("not a workspace")
    top = workspace.get("blocks", {})
    stacks = top.get("blocks", []) if isinstance(top, dict) else None
    if not isinstance(stacks, list):
        raise ValueError("not a workspace")
    found: list[dict] = []
    pending = list(reversed(stacks))
    while pending:
        block = pending.pop()
        if not isinstance(block, dict) or not _enabled(block):
            continue
        found.append(block)
        if len(found) > MAX_BLOCKS:
            raise ValueError("too many blocks")
        following = block.get("next")
        if isinstance(following, dict):
            pending.append(following.get("block"))
        inputs = block.get("inputs")
        if isinstance(inputs, dict):
            for connection in reversed(list(inputs.values())):
                if isinstance(connection, dict):
                    pending.append(connection.get("block"))
    return found


def _enabled(block: dict) -> bool:
    reasons = block.get("disabledReasons")
    return block.get("enabled", True) is not False and not reasons


def uses_block(
    block_type: str, blocks: list[dict], _: Callable[[str], str] = _same
) -> tuple[bool, str]:
    """(passed, why): whether a block of the type, or of the group ("loop", "condition"), is
    among ``blocks``."""
    wanted = GROUPS.get(block_type, (block_type,))
    count = sum(1 for block in blocks if block.get("type") in wanted)
    if block_type == "loop":
        if count:
            return (True, _("the program uses a loop"))
        return (False, _("the program has no loop (a repeat, while, until or for block)"))
    if block_type == "condition":
        if count:
            return (True, _("the program uses a condition"))
        return (False, _("the program has no condition (an if block)"))
    words = {"block": block_type}
    if count:
        return (True, _("the program uses the block %(block)s") % words)
    return (False, _("the program does not use the block %(block)s") % words)


def max_blocks(most: int, blocks: list[dict], _: Callable[[str], str] = _same) -> tuple[bool, str]:
    """(passed, why): whether there are at most ``most`` blocks."""
    words = {"count": len(blocks), "most": most}
    if len(blocks) <= most:
        return (True, _("the program has %(count)s blocks, at most %(most)s") % words)
    return (
        False,
        _("the program has %(count)s blocks; the exercise allows at most %(most)s") % words,
    )
