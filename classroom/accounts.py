"""A class's students made in bulk: accounts from a list of names, with one-time passwords.

A teacher pastes names (one a line) or uploads a CSV whose rows are ``name`` or
``username,full name``. Each name becomes an account whose username is the name made a slug
(``Ana Maria Silva`` -> ``ana-maria-silva``; ``-2``, ``-3``... when taken); an entry that is
an existing account's username puts that account in the class, with no new password. A new
account gets a one-time password (a OneTimePassword row: it must choose its own at its first
sign-in), shown once, on the printable sheet or in the API's answer, and never kept in clear.

An existing account that is staff or teaches a class is refused as a student: a class's
teachers see its students' programs, and a teacher could otherwise read a colleague's.
"""

from __future__ import annotations

import csv
import io
import re
import secrets
from dataclasses import dataclass

from django.contrib.auth import get_user_model
from django.contrib.auth.models import Group
from django.db import IntegrityError, transaction
from django.utils.text import slugify
from django.utils.translation import gettext as _

from classroom.models import JOIN_ALPHABET, Classroom, OneTimePassword, new_join_code
from robotide.models import ClassTeacher

#: How many students one request may add (a school class is 20-40).
MAX_STUDENTS = 200
#: Characters of a one-time password (JOIN_ALPHABET: no 0/O, 1/I/L): 31**10, about 2**49.
PASSWORD_LENGTH = 10
USERNAME_LENGTH = 30
_USERNAME = re.compile(r"^[\w.@+-]+\Z", re.ASCII)
_HEADER_WORDS = {
    "name", "names", "full name", "username", "user", "login", "student", "surname",
    "nome", "nome completo", "usuário", "usuario", "aluno", "aluna", "sobrenome",
}  # fmt: skip


class AccountsError(ValueError):
    """A list that cannot be made into accounts: ``index`` of the entry (None: the whole list)
    and what is wrong with it."""

    def __init__(self, message: str, index: int | None = None):
        super().__init__(message)
        self.index = index


@dataclass(frozen=True)
class NewAccount:
    username: str
    full_name: str
    password: str | None  # the one-time password, for a new account only
    created: bool


@dataclass(frozen=True)
class Entry:
    """One line of a teacher's list: a name, or a username and a full name."""

    name: str = ""
    username: str = ""


def new_password() -> str:
    """A one-time password: read off a sheet and typed once, so no look-alike characters."""
    return "".join(secrets.choice(JOIN_ALPHABET) for _ in range(PASSWORD_LENGTH))


def entries_from_text(text: str) -> list[Entry]:
    """A pasted list (a name a line) or a CSV's text (rows ``name`` or ``username,full name``,
    comma or semicolon separated, an optional header row): the entries, blank lines skipped."""
    text = text.lstrip("\ufeff")
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        return []
    try:
        dialect = csv.Sniffer().sniff("\n".join(lines[:20]), delimiters=",;\t")
        delimiter = dialect.delimiter
    except csv.Error:
        delimiter = ","
    rows = list(csv.reader(io.StringIO("\n".join(lines)), delimiter=delimiter))
    if rows and all(cell.strip().lower() in _HEADER_WORDS for cell in rows[0] if cell.strip()):
        rows = rows[1:]
    entries = []
    for row in rows:
        cells = [cell.strip() for cell in row if cell.strip()]
        if not cells:
            continue
        if len(cells) == 1:
            entries.append(Entry(name=cells[0]))
        else:
            entries.append(Entry(username=cells[0], name=" ".join(cells[1:])))
    return entries


def as_entry(value) -> Entry:
    if isinstance(value, Entry):
        return value
    if isinstance(value, tuple | list) and len(value) == 2:
        return Entry(username=str(value[0]).strip(), name=str(value[1]).strip())
    return Entry(name=str(value).strip())


def username_base(name: str) -> str:
    """``Ana María Silva`` -> ``ana-maria-silva`` (ASCII, at most USERNAME_LENGTH)."""
    base = slugify(name)[:USERNAME_LENGTH].strip("-_")
    return base or "student"


def _split_name(full_name: str) -> tuple[str, str]:
    first, _, last = full_name.strip().partition(" ")
    return first[:150], last.strip()[:150]


def _free_username(base: str, taken: set[str]) -> str:
    User = get_user_model()
    name, n = base, 1
    while name.lower() in taken or User.objects.filter(username__iexact=name).exists():
        n += 1
        name = f"{base[: USERNAME_LENGTH - len(str(n)) - 1]}-{n}"
    return name


def _member_named(group: Group, full_name: str, base: str):
    """A student of ``group`` made from this name before (username ``base`` or ``base-N``,
    the same full name), or None."""
    first, last = _split_name(full_name)
    pattern = rf"^{re.escape(base)}(-[0-9]+)?$"
    return (
        group.user_set.filter(username__iregex=pattern, first_name=first, last_name=last)
        .order_by("pk")
        .first()
    )


def _refuse_as_student(user, index: int) -> None:
    if user.is_staff or user.is_superuser or ClassTeacher.objects.filter(user=user).exists():
        raise AccountsError(
            _("%(username)s is a teacher's or staff account: it cannot join a class as a student")
            % {"username": user.username},
            index,
        )


def create_students(group: Group, names: list, issued_by) -> list[NewAccount]:
    """Put the accounts ``names`` name in ``group``, making those that do not exist yet (each
    with a one-time password). ``names``: strings (a name, or an existing username), Entries,
    or (username, full name) pairs. All or nothing: AccountsError names the entry at fault."""
    entries = [as_entry(value) for value in names]
    if len(entries) > MAX_STUDENTS:
        raise AccountsError(
            _("at most %(max)s students at once; this list has %(count)s")
            % {"max": MAX_STUDENTS, "count": len(entries)}
        )
    User = get_user_model()
    made: list[NewAccount] = []
    seen: set[int] = set()
    taken: set[str] = set()  # usernames given in this list (not yet saved)
    with transaction.atomic():
        for index, entry in enumerate(entries):
            if not entry.name and not entry.username:
                raise AccountsError(_("an empty name"), index)
            if len(entry.name) > 150 or len(entry.username) > 150:
                raise AccountsError(_("a name is at most 150 characters"), index)
            lookup = entry.username or entry.name
            existing = User.objects.filter(username__iexact=lookup).first()
            if existing is not None:
                _refuse_as_student(existing, index)
                if existing.pk not in seen:
                    seen.add(existing.pk)
                    existing.groups.add(group)
                    made.append(
                        NewAccount(existing.username, existing.get_full_name(), None, False)
                    )
                continue
            if entry.username:
                if not _USERNAME.match(entry.username) or len(entry.username) > USERNAME_LENGTH:
                    raise AccountsError(
                        _(
                            "%(username)s is not a username: at most %(max)s letters, digits"
                            " and . @ + - _"
                        )
                        % {"username": repr(entry.username), "max": USERNAME_LENGTH},
                        index,
                    )
                if entry.username.lower() in taken:
                    raise AccountsError(
                        _("%(username)s is in the list twice") % {"username": entry.username},
                        index,
                    )
                username = entry.username
            else:
                # The same list pasted again: its students are in the class already.
                member = _member_named(group, entry.name, username_base(entry.name))
                if member is not None:
                    if member.pk not in seen:
                        seen.add(member.pk)
                        made.append(NewAccount(member.username, entry.name, None, False))
                    continue
                username = _free_username(username_base(entry.name), taken)
            taken.add(username.lower())
            full_name = entry.name or ""
            first, last = _split_name(full_name)
            password = new_password()
            try:
                with transaction.atomic():
                    user = User.objects.create_user(
                        username, password=password, first_name=first, last_name=last
                    )
            except IntegrityError:
                raise AccountsError(
                    _("%(username)s was taken meanwhile: try again") % {"username": username},
                    index,
                ) from None
            OneTimePassword.objects.update_or_create(user=user, defaults={"issued_by": issued_by})
            user.groups.add(group)
            seen.add(user.pk)
            made.append(NewAccount(user.username, full_name, password, True))
    return made


def create_class(name: str, teacher) -> Group:
    """A new class (a Group with a Classroom row and a join code) taught by ``teacher``;
    AccountsError if the name is empty or a class of that name exists."""
    name = (name or "").strip()
    if not name:
        raise AccountsError(_("a class needs a name"))
    if len(name) > 150:
        raise AccountsError(_("a class's name is at most 150 characters"))
    if Group.objects.filter(name__iexact=name).exists():
        raise AccountsError(_("there is a class named %(name)s already") % {"name": repr(name)})
    try:
        with transaction.atomic():
            group = Group.objects.create(name=name)
            ClassTeacher.objects.create(group=group, user=teacher)
            Classroom.objects.create(group=group, join_code=free_join_code(), created_by=teacher)
    except IntegrityError:
        raise AccountsError(
            _("there is a class named %(name)s already") % {"name": repr(name)}
        ) from None
    return group


def free_join_code() -> str:
    """A join code no class has (31**8 codes: a clash is rare, but the column is unique)."""
    while True:
        code = new_join_code()
        if not Classroom.objects.filter(join_code=code).exists():
            return code
