"""A user's programs as a zip of plain files, and back.

The zip holds one file per program, named ``<slug of the name><extension of its language>``
(``-2``, ``-3``... on clashes), and ``manifest.json``::

    {"format": "robotide-programs", "version": 1, "exported": "2025-01-31T12:00:00+00:00",
     "programs": [{"name": "Compass", "language": "python", "file": "compass.py",
                   "created": "...", "updated": "...", "revisions": 3, "origin": ""}]}

so the files can be edited with any text editor (as on the paper's SD card) and imported again.

Import reads the manifest when there is one (a program's name and language); a file it does
not list is placed by its extension, and one that nothing places is reported, as is a file that
is not UTF-8 text or is larger than a program may be. Folders: the one folder every entry lies
in, as zipping a folder makes, is looked through; a deeper folder refuses the zip (programs
are flat files; importing part of a project tree would surprise more than help). macOS'
``__MACOSX/`` resource forks are ignored.

Errors that refuse the whole zip (nothing is imported)::

    ArchiveError
     +-- NotAZip           not a zip, or a damaged one
     +-- ArchiveTooLarge   too many files or too many bytes once uncompressed (zip bombs)
     +-- BadArchive        unsafe or nested paths, a manifest that is not ours
"""

import io
import json
import re
import stat
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import PurePosixPath

from django.db import transaction
from django.db.models import Count
from django.utils import timezone
from django.utils.text import slugify
from django.utils.translation import gettext as _

from programs.forms import MAX_NAME, free_name
from programs.languages import LANGUAGES, language_for_filename
from programs.models import MAX_SOURCE_BYTES, Program
from robotide import names

FORMAT = "robotide-programs"
VERSION = 1
MANIFEST = "manifest.json"
MAX_FILES = 1000
MAX_TOTAL_BYTES = 50 * 1024 * 1024
MAX_MANIFEST_BYTES = 1024 * 1024
IGNORED_FOLDERS = ("__MACOSX/",)
MAX_ORIGIN = Program._meta.get_field("origin").max_length


class ArchiveError(Exception):
    """The zip is refused as a whole; nothing of it was imported."""


class NotAZip(ArchiveError):
    pass


class ArchiveTooLarge(ArchiveError):
    pass


class BadArchive(ArchiveError):
    pass


# -- export -----------------------------------------------------------------------------------


def export_zip(programs) -> bytes:
    """The programs (a queryset) as a zip of plain files with a manifest."""
    entries, taken = [], set()
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        for program in programs.annotate(revision_count=Count("revisions")).order_by("name"):
            filename = _unique_filename(program, taken)
            info = zipfile.ZipInfo(filename, date_time=_zip_time(program.updated))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (stat.S_IFREG | 0o644) << 16
            zf.writestr(info, program.source.encode())
            entries.append(
                {
                    "name": program.name,
                    "language": program.language,
                    "file": filename,
                    "created": program.created.isoformat(),
                    "updated": program.updated.isoformat(),
                    "revisions": program.revision_count,
                    "origin": program.origin,
                }
            )
        manifest = {
            "format": FORMAT,
            "version": VERSION,
            "exported": timezone.now().isoformat(),
            "programs": entries,
        }
        zf.writestr(MANIFEST, json.dumps(manifest, indent=2, ensure_ascii=False) + "\n")
    return buffer.getvalue()


def _unique_filename(program: Program, taken: set[str]) -> str:
    stem, ext = slugify(program.name) or "program", program.lang.extension
    candidate, n = stem + ext, 1
    while candidate in taken or candidate == MANIFEST:
        n += 1
        candidate = f"{stem}-{n}{ext}"
    taken.add(candidate)
    return candidate


def _zip_time(moment) -> tuple[int, int, int, int, int, int]:
    local = timezone.localtime(moment)
    return max(local.timetuple()[:6], (1980, 1, 1, 0, 0, 0))


# -- import -----------------------------------------------------------------------------------


@dataclass
class Imported:
    file: str
    program: Program


@dataclass
class Skipped:
    file: str
    why: str


@dataclass
class ImportReport:
    created: list[Imported] = field(default_factory=list)
    updated: list[Imported] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)

    def as_dict(self) -> dict:
        def program(entry: Imported) -> dict:
            return {"id": entry.program.pk, "name": entry.program.name, "file": entry.file}

        return {
            "created": [program(e) for e in self.created],
            "updated": [program(e) for e in self.updated],
            "skipped": [{"file": s.file, "why": s.why} for s in self.skipped],
        }

    def lines(self) -> list[str]:
        """For people: one line per file."""
        return [
            *(_created(e) for e in self.created),
            *(_updated(e) for e in self.updated),
            *(
                _("skipped %(file)s: %(why)s") % {"file": s.file, "why": s.why}
                for s in self.skipped
            ),
        ]

    def summary(self) -> str:
        counts = {"created": len(self.created), "updated": len(self.updated)}
        counts["skipped"] = len(self.skipped)
        return _("%(created)s created, %(updated)s updated, %(skipped)s skipped") % counts


def _created(entry: Imported) -> str:
    return _("created %(name)s from %(file)s") % {
        "name": repr(entry.program.name),
        "file": entry.file,
    }


def _updated(entry: Imported) -> str:
    return _("updated %(name)s from %(file)s") % {
        "name": repr(entry.program.name),
        "file": entry.file,
    }


def _mb(limit: int) -> dict:
    return {"mb": limit // 2**20}


def import_zip(data: bytes, user, *, filename: str = "a zip", replace: bool = False):
    """Create (or with `replace`, revise) `user`'s programs from a zip; all or nothing.

    A program named as one the user has gets " (2)" etc., unless `replace`: then the existing
    program gets the file as a new revision (its history stays). Raises ArchiveError.
    """
    if len(data) > MAX_TOTAL_BYTES:
        raise ArchiveTooLarge(_("The zip is larger than %(mb)s MB.") % _mb(MAX_TOTAL_BYTES))
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
    except (zipfile.BadZipFile, ValueError, EOFError) as exc:
        raise NotAZip(_("Not a zip file (%(why)s).") % {"why": exc}) from None
    except NotImplementedError as exc:
        raise NotAZip(_("A zip this robotide cannot read (%(why)s).") % {"why": exc}) from None
    basename = PurePosixPath(filename.replace("\\", "/")).name
    origin = f"imported from {basename}"[:MAX_ORIGIN]
    report = ImportReport()
    with zf, transaction.atomic():
        files, twice = _files(zf)
        manifest = _manifest(zf, files.pop(MANIFEST, None))
        for name, info in files.items():
            entry = manifest.pop(name, None) or {}
            try:
                language, source = _read_program(zf, name, info, entry)
            except _Skip as skip:
                report.skipped.append(Skipped(name, str(skip)))
                continue
            wanted = _program_name(name, entry)
            program, done = _save(user, wanted, language, source, origin, replace)
            if done == "unchanged":
                report.skipped.append(
                    Skipped(name, _("the same as %(name)s already") % {"name": repr(program.name)})
                )
            else:
                getattr(report, done).append(Imported(name, program))
    for name in twice:
        report.skipped.append(Skipped(name, _("in the zip twice: the first one counts")))
    for name in manifest:
        report.skipped.append(Skipped(name, _("listed in the manifest but not in the zip")))
    return report


def _files(zf: zipfile.ZipFile) -> tuple[dict[str, zipfile.ZipInfo], list[str]]:
    """The zip's files by the name the manifest knows them by, after the safety checks."""
    infos = zf.infolist()
    if len(infos) > MAX_FILES:
        raise ArchiveTooLarge(_("The zip holds more than %(n)s files.") % {"n": MAX_FILES})
    if sum(info.file_size for info in infos) > MAX_TOTAL_BYTES:
        raise ArchiveTooLarge(
            _("The zip's files come to more than %(mb)s MB uncompressed.") % _mb(MAX_TOTAL_BYTES)
        )
    entries = []
    for info in infos:
        path = info.filename.replace("\\", "/")
        if path.startswith("/") or re.match(r"[A-Za-z]:(/|$)", path):
            raise BadArchive(_("%(file)s in the zip is an absolute path.") % _file(info))
        if ".." in path.split("/"):
            raise BadArchive(_("%(file)s in the zip climbs out of it ('..').") % _file(info))
        parts = PurePosixPath(path).parts
        if parts and not path.startswith(IGNORED_FOLDERS) and not info.is_dir():
            entries.append((parts, info))
    # Zipping a folder puts every file in it: look through that one folder.
    tops = {parts[0] for parts, _info in entries}
    if len(tops) == 1 and all(len(parts) > 1 for parts, _info in entries):
        entries = [(parts[1:], info) for parts, info in entries]
    files: dict[str, zipfile.ZipInfo] = {}
    twice = []
    for parts, info in entries:
        if len(parts) > 1:
            raise BadArchive(
                _("%(file)s is in a folder: put the program files at the top of the zip.")
                % _file(info)
            )
        if parts[0] in files:
            twice.append(parts[0])
        else:
            files[parts[0]] = info
    return files, twice


def _file(info: zipfile.ZipInfo) -> dict:
    return {"file": repr(info.filename)}


def _manifest(zf: zipfile.ZipFile, info: zipfile.ZipInfo | None) -> dict[str, dict]:
    """The manifest's entries by file name ({} without a manifest)."""
    if info is None:
        return {}
    try:
        if info.file_size > MAX_MANIFEST_BYTES:
            raise ValueError(_("larger than %(kb)s KB") % {"kb": MAX_MANIFEST_BYTES // 1024})
        manifest = json.loads(_read(zf, info, MAX_MANIFEST_BYTES).decode("utf-8-sig"))
        if not isinstance(manifest, dict) or manifest.get("format", FORMAT) != FORMAT:
            raise ValueError(_("not a robotide manifest"))
        version = manifest.get("version", VERSION)
        if not isinstance(version, int) or version > VERSION:
            raise ValueError(
                _("format version %(version)s: made by a newer robotide?")
                % {"version": repr(version)}
            )
        entries = manifest.get("programs", [])
        if not isinstance(entries, list) or not all(
            isinstance(e, dict) and isinstance(e.get("file"), str) for e in entries
        ):
            raise ValueError(_('"programs" must be a list of objects, each with its "file"'))
    # JSONDecodeError is a ValueError; deep nesting is a RecursionError
    except (ValueError, RecursionError, NotImplementedError) as exc:
        raise BadArchive(
            _("The zip's %(manifest)s is unusable: %(why)s.") % {"manifest": MANIFEST, "why": exc}
        ) from None
    return {entry["file"]: entry for entry in entries}


def _save(user, name, language, source, origin, replace) -> tuple[Program, str]:
    """The program made or revised, and which: "created", "updated" or "unchanged"."""
    existing = user.programs.filter(name=name).first() if replace else None
    if existing is None:
        program = Program.objects.create(
            owner=user, name=free_name(user, name), language=language, origin=origin
        )
        program.save_source(source, user)
        return program, "created"
    if (existing.source, existing.language) == (source, language):
        return existing, "unchanged"
    existing.language = language
    existing.save_source(source, user)  # a new revision: the history stays
    return existing, "updated"


def _read(zf: zipfile.ZipFile, info: zipfile.ZipInfo, limit: int) -> bytes:
    """At most `limit` bytes of a file of the zip; a damaged zip is NotAZip."""
    try:
        with zf.open(info) as member:
            return member.read(limit)
    # A header that lies sends zipfile seeking before the start (ValueError) or decoding a
    # name that is not UTF-8 (UnicodeDecodeError, a ValueError too).
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError) as exc:
        raise NotAZip(_("The zip is damaged (%(why)s).") % {"why": exc}) from None
    except RuntimeError as exc:  # encrypted
        raise NotAZip(_("A zip this robotide cannot read (%(why)s).") % {"why": exc}) from None


class _Skip(Exception):
    """Why one file is not imported; the others are."""


def _read_program(zf: zipfile.ZipFile, name: str, info: zipfile.ZipInfo, entry: dict):
    """(language, source) of one file of the zip, or _Skip saying why not."""
    declared = entry.get("language") if isinstance(entry.get("language"), str) else None
    placed = language_for_filename(name)
    language = declared if declared in LANGUAGES else getattr(placed, "name", None)
    if language is None:
        if declared:
            raise _Skip(_("unknown language %(name)s") % {"name": repr(declared)})
        suffix = PurePosixPath(name).suffix
        if not suffix:
            raise _Skip(_("no extension"))
        raise _Skip(_("no language has the extension %(ext)s") % {"ext": repr(suffix)})
    if stat.S_ISLNK(info.external_attr >> 16):
        raise _Skip(_("a symbolic link, not a file"))
    if info.flag_bits & 0x1:
        raise _Skip(_("encrypted"))
    too_large = _Skip(
        _("larger than %(kb)s KB, the most a program may be") % {"kb": MAX_SOURCE_BYTES // 1024}
    )
    if info.file_size > MAX_SOURCE_BYTES:
        raise too_large
    try:
        raw = _read(zf, info, MAX_SOURCE_BYTES + 1)
    except NotImplementedError:
        raise _Skip(_("compressed in a way this robotide cannot read")) from None
    if len(raw) > MAX_SOURCE_BYTES:  # zipfile stops at the stated size: belt and braces
        raise too_large
    try:
        source = raw.decode("utf-8-sig")  # a text editor may have put a byte-order mark
    except UnicodeDecodeError:
        raise _Skip(_("not UTF-8 text")) from None
    if "\x00" in source:
        raise _Skip(_("not text (it has NUL bytes)"))
    return language, source.replace("\r\n", "\n")


def _program_name(name: str, entry: dict) -> str:
    wanted = entry.get("name") if isinstance(entry.get("name"), str) else ""
    wanted = names.cleaned(wanted)  # a zip's names were never checked as names
    stem = names.cleaned(PurePosixPath(name).stem)
    return wanted.strip()[:MAX_NAME] or stem.strip()[:MAX_NAME] or "imported"


def export_filename(user) -> str:
    return f"robotide-{user.get_username()}-{timezone.localdate().isoformat()}.zip"
