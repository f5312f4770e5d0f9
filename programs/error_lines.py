"""Where a line of a run's output points in the program: the line for the editor to mark.

Each interpreter says it its own way: one registry entry per language, keyed like
programs.languages.LANGUAGES. Only the program's own file counts: tracebacks also name the Robot
API client library and the interpreter's own files, lines the user cannot edit. A file is known
by its name alone, so the path inside the run box and the one on the host both match.
"""

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import PurePosixPath


@dataclass(frozen=True)
class ErrorPlace:
    line: int  # 1-based line in the program
    column: int | None  # 1-based, when the format gives one
    message: str  # the error's own text, when the line carries it (else "")


@dataclass(frozen=True)
class _Format:
    """How one interpreter reports an error.

    A head begins an error and may say where; a frame is one line of its traceback; a start
    begins an error without saying where. Patterns have the groups `path` and `line`, and `col`,
    `msg` and `near` where the format gives them. `compile_failed` is a line saying the program
    did not compile: then the first error is the cause and the ones after it follow from it.
    """

    heads: tuple[re.Pattern[str], ...] = ()
    frames: tuple[re.Pattern[str], ...] = ()
    start: re.Pattern[str] | None = None
    innermost_first: bool = True  # the traceback's order; Python's is the other way round
    compile_failed: re.Pattern[str] | None = None


@dataclass(frozen=True)
class _Found:
    path: str
    place: ErrorPlace
    head: bool


PYTHON = _Format(
    # a traceback's frame, or the first line of a SyntaxError
    frames=(re.compile(r'^[\s|]*File "(?P<path>[^"]+)", line (?P<line>\d+)(?:, in .*)?$'),),
    start=re.compile(r"^[\s|+-]*(?:Exception Group )?Traceback \(most recent call last\):"),
    innermost_first=False,
)

FORMATS: dict[str, _Format | None] = {  # None: no line of the source to mark
    "python": PYTHON,
    "perl": _Format(
        frames=(re.compile(r"^\s+\S.* called at (?P<path>\S+) line (?P<line>\d+)\b"),),
        # `boom at x.pl line 4.`, `syntax error at x.pl line 4, near "my "`, `..., <STDIN> line 2.`
        heads=(
            re.compile(
                r"^(?P<msg>.*?) at (?P<path>\S+) line (?P<line>\d+)"
                r"(?:, <\S+> (?:line|chunk) \d+)?(?P<near>, near .*)?\.?$"
            ),
        ),
        compile_failed=re.compile(
            r"^(?:Execution of .* aborted due to compilation errors|.* had compilation errors"
            r"|.* has too many errors)\.$"
        ),
    ),
    "ruby": _Format(
        frames=(re.compile(r"^\s+from (?P<path>[^\s:]+):(?P<line>\d+)(?::|$)"),),
        # `x.rb:5:in 'f': boom (RuntimeError)` (a backtick before 3.4), `x.rb:3: syntax error`,
        # `ruby: x.rb:3: syntax errors found` (3.4)
        heads=(
            re.compile(
                r"^(?:\S+: )?(?P<path>[^\s:]+):(?P<line>\d+):(?:in [`'][^']*':)? ?(?P<msg>.*)$"
            ),
        ),
        compile_failed=re.compile(r"^(?:\S+: )?[^\s:]+:\d+: syntax errors?\b"),
    ),
    "lua": _Format(
        frames=(re.compile(r"^\t(?P<path>[^\s:]+):(?P<line>\d+): in "),),
        # `lua5.4: x.lua:8: boom`, the interpreter's name as it was started
        heads=(re.compile(r"^(?:\S+: )?(?P<path>[^\s:]+):(?P<line>\d+):(?P<msg>.*)$"),),
    ),
    "javascript": _Format(
        frames=(re.compile(r"^\s+at (?:.* \()?(?P<path>\S+?):(?P<line>\d+):(?P<col>\d+)\)?$"),),
        heads=(re.compile(r"^(?P<path>\S+):(?P<line>\d+)$"),),  # before the source and caret
    ),
    "tcl": _Format(
        # `(procedure "turn" line 3)` counts from the proc's first line: only a file's is ours
        frames=(re.compile(r'^\s*\(file "(?P<path>[^"]+)" line (?P<line>\d+)\)$'),),
        start=re.compile(r"^\s+while (?:executing|compiling)$"),
    ),
    "shell": _Format(
        heads=(
            re.compile(r"^(?P<path>[^:]+): line (?P<line>\d+): (?P<msg>.*)$"),  # bash
            re.compile(r"^(?P<path>[^:]+): (?P<line>\d+): (?P<msg>.*)$"),  # dash
        ),
    ),
    # What runs is the Python made of the blocks: its line is the Python's, which the
    # workbench turns into the block that made it (programs.blocks.to_python_mapped).
    "blocks": PYTHON,
}

# A language whose program runs as another file: the extension of the file that runs (as
# programs.languages says), the one its errors name.
RUNS_AS = {"blocks": ".py"}


def error_place(language: str, text: str, program_file: str) -> ErrorPlace | None:
    """The place in the user's program that one output line (stderr or stdout) points at,
    or None."""
    fmt = _format(language)
    found = fmt and _find(fmt, text)
    program_file = _running(language, program_file)
    return found.place if found and _same_file(found.path, program_file) else None


def last_error_place(language: str, lines: Iterable[str], program_file: str) -> ErrorPlace | None:
    """The place to mark for a block of output: of the last error that names the program, the
    deepest frame in the program's file. An error raised inside a library so marks the
    program's line that called it. When the program did not compile, its first error."""
    fmt = _format(language)
    if fmt is None:
        return None
    program_file = _running(language, program_file)
    first = place = None
    taken = False  # the current error's place is found
    for text in lines:
        found = _find(fmt, text)
        if (found and found.head) or (fmt.start and fmt.start.search(text)):
            taken = False  # another error begins
        if found and _same_file(found.path, program_file) and not (fmt.innermost_first and taken):
            place, taken = found.place, True
            first = first or place
        if fmt.compile_failed and fmt.compile_failed.search(text):
            return first  # the errors after the first follow from it
    return place


def _format(language: str) -> _Format | None:
    try:
        return FORMATS[language]
    except KeyError:
        raise ValueError(f"No error format for the language {language!r}.") from None


def _running(language: str, program_file: str) -> str:
    """The file that runs for `program_file`: itself, or what it is made into."""
    if language not in RUNS_AS:
        return program_file
    return str(PurePosixPath(program_file).with_suffix(RUNS_AS[language]))


def _find(fmt: _Format, text: str) -> _Found | None:
    text = text.rstrip("\r\n")
    # frames first: a Perl frame (`called at x.pl line 4`) would pass for a head too
    for patterns, head in ((fmt.frames, False), (fmt.heads, True)):
        for pattern in patterns:
            if m := pattern.search(text):
                return _Found(m["path"], _place(m), head)
    return None


def _place(m: re.Match[str]) -> ErrorPlace:
    groups = m.groupdict()
    column = int(groups["col"]) if groups.get("col") else None
    message = ((groups.get("msg") or "") + (groups.get("near") or "")).strip()
    return ErrorPlace(int(m["line"]), column, message)


def _same_file(reported: str, program_file: str) -> bool:
    name = PurePosixPath(program_file).name
    reported = reported.removeprefix("file://")  # Node.js's ES modules
    if reported.startswith("..."):  # Lua keeps only the tail of a long path
        tail = reported[3:]
        return name.endswith(tail) if "/" not in tail else PurePosixPath(tail).name == name
    return PurePosixPath(reported).name == name
