"""What a debugger's breakpoints, watches and commands may be: checked wherever they enter
(the workbench's start and command requests, the agent's channel, robots.messages), so that a
bad one is refused as a whole with a reason. No Django: the agent's message check imports it.

    spec     {"breakpoints": [breakpoint, ...], "watches": [expression, ...]}
    breakpoint {"line": n, "condition": text or null}  (a line of the program that runs)
             or {"block": block id, "condition": ...}   (a blocks program's block)
    command  one of COMMANDS

The protocol they travel in is documented in programs/clients/PROTOCOL.md, "The debugger".
"""

MAX_BREAKPOINTS = 200
MAX_WATCHES = 50
MAX_EXPRESSION = 500  # characters of a condition or a watch
MAX_BLOCK_ID = 100
MAX_LINE = 1_000_000

# continue: run to the next breakpoint; step_over / step_into / step_out: as in every
# debugger; pause: stop where it is now; stop: end the run; update: new breakpoints or
# watches only (while paused, the watches are evaluated again and the pause is said again).
COMMANDS = ("continue", "step_over", "step_into", "step_out", "pause", "stop", "update")


def check_spec(spec) -> str | None:
    """None if `spec` is a debugger spec as above (either key may be absent), else why not."""
    if not isinstance(spec, dict) or set(spec) - {"breakpoints", "watches"}:
        return "must be an object with 'breakpoints' and 'watches'"
    why = check_breakpoints(spec.get("breakpoints", []))
    if why is None:
        why = check_watches(spec.get("watches", []))
    return why


def check_breakpoints(breakpoints) -> str | None:
    if not isinstance(breakpoints, list) or len(breakpoints) > MAX_BREAKPOINTS:
        return f"breakpoints must be a list of at most {MAX_BREAKPOINTS}"
    for point in breakpoints:
        if not isinstance(point, dict) or set(point) - {"line", "block", "condition"}:
            return "a breakpoint is {'line': n} or {'block': id}, with an optional 'condition'"
        line, block = point.get("line"), point.get("block")
        if (line is None) == (block is None):
            return "a breakpoint has a line or a block, not both"
        if line is not None and (type(line) is not int or not 0 < line <= MAX_LINE):
            return f"a breakpoint's line must be a whole number from 1 to {MAX_LINE}"
        if block is not None and (not isinstance(block, str) or not 0 < len(block) <= MAX_BLOCK_ID):
            return f"a breakpoint's block must be an id of 1 to {MAX_BLOCK_ID} characters"
        condition = point.get("condition")
        if condition is not None and (
            not isinstance(condition, str) or len(condition) > MAX_EXPRESSION
        ):
            return f"a breakpoint's condition must be a text of at most {MAX_EXPRESSION} characters"
    return None


def check_watches(watches) -> str | None:
    if not isinstance(watches, list) or len(watches) > MAX_WATCHES:
        return f"watches must be a list of at most {MAX_WATCHES}"
    for watch in watches:
        if not isinstance(watch, str) or not 0 < len(watch) <= MAX_EXPRESSION:
            return f"a watch must be an expression of 1 to {MAX_EXPRESSION} characters"
    return None


def check_command(command) -> str | None:
    if command not in COMMANDS:
        return f"must be one of {', '.join(COMMANDS)}"
    return None
