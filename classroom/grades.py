"""A class's grades: students x exercises, each cell the counted attempt (best or latest, as the
exercise says), and the same as CSV for a school's gradebook or LMS."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from datetime import datetime

from django.contrib.auth.models import Group
from django.db.models import Count, Max
from django.utils.translation import gettext as _

from classroom.checking import counted_attempt
from classroom.models import Attempt, Exercise

#: A spreadsheet reads a cell starting with one of these as a formula (CSV injection).
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


@dataclass
class Cell:
    score: float | None  # the counted attempt's; None: none counted yet
    max_score: float
    attempts: int  # how many the student made
    last: datetime | None  # when the latest was made
    late: bool  # the counted attempt was made after the due date
    passed: bool
    attempt_id: int | None  # the counted attempt


@dataclass
class Grid:
    group: Group
    students: list  # users, by username
    exercises: list[Exercise]
    cells: dict[tuple[int, int], Cell] = field(default_factory=dict)  # (student, exercise)

    def cell(self, student, exercise) -> Cell:
        return self.cells[(student.pk, exercise.pk)]

    def rows(self):
        """(student, [cell for each exercise]) for each student."""
        for student in self.students:
            yield student, [self.cell(student, exercise) for exercise in self.exercises]


def grid(group: Group) -> Grid:
    """The class's students (its members, teachers left out) by the class's exercises."""
    teachers = group.teachers.values_list("user_id", flat=True)
    students = list(group.user_set.exclude(pk__in=teachers).order_by("username"))
    exercises = list(Exercise.objects.filter(group=group).order_by("due", "title", "pk"))
    made = {
        (row["student_id"], row["exercise_id"]): row
        for row in Attempt.objects.filter(exercise__in=exercises, student__in=students)
        .values("student_id", "exercise_id")
        .annotate(count=Count("pk"), last=Max("created"))
    }
    table = Grid(group, students, exercises)
    for exercise in exercises:
        for student in students:
            row = made.get((student.pk, exercise.pk))
            counted = counted_attempt(exercise, student) if row else None
            table.cells[(student.pk, exercise.pk)] = Cell(
                score=counted.score if counted else None,
                max_score=counted.max_score if counted else exercise.max_score,
                attempts=row["count"] if row else 0,
                last=row["last"] if row else None,
                late=bool(counted and counted.late),
                passed=bool(counted and counted.passed),
                attempt_id=counted.pk if counted else None,
            )
    return table


def safe_cell(value) -> str:
    """A cell as text, never read as a formula: one starting with = + - @ gets a ' before it
    (OWASP's advice; a student may call themself "=HYPERLINK(...)")."""
    text = "" if value is None else str(value)
    return "'" + text if text.startswith(FORMULA_STARTS) else text


def number(value: float | None) -> str:
    return "" if value is None else f"{value:g}"


def grades_csv(group: Group) -> str:
    """One row a student: username, name, then each exercise's score (empty: none counted);
    a header row of the exercises' titles."""
    table = grid(group)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\r\n")
    header = [_("username"), _("name")] + [exercise.title for exercise in table.exercises]
    writer.writerow([safe_cell(value) for value in header])
    for student, cells in table.rows():
        row = [student.username, student.get_full_name()] + [number(c.score) for c in cells]
        writer.writerow([safe_cell(value) for value in row])
    return out.getvalue()


def csv_filename(group: Group) -> str:
    from django.utils.text import slugify

    return f"grades-{slugify(group.name) or group.pk}.csv"
