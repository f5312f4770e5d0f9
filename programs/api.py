from datetime import datetime
from typing import Literal

from django.db import IntegrityError
from django.db.models import Count
from django.http import HttpResponse
from django.utils.http import content_disposition_header
from django.utils.translation import gettext as _
from ninja import Field, File, Form, Router, Schema, UploadedFile
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import field_validator, model_validator

from programs import archive, outbound, watch_pass
from programs.access import (
    EDIT,
    OWN,
    get_program_for_user,
    get_run_for_user,
    programs_for_user,
)
from programs.forms import already_named
from programs.languages import LANGUAGES, get_language
from programs.models import MAX_SOURCE_BYTES, Program, Run
from programs.runlog import download
from robotide import names
from robotide.names import Name
from robotide.schemas import Body
from robots import run_queue, stops
from robots.availability import robot_to_run_on
from robots.models import get_robot_for_user
from robots.runs import request_stop, start_run

programs_router = Router(tags=["programs"])
runs_router = Router(tags=["runs"])

# The allowed values in the OpenAPI schema; the validators below give the clearer errors.
LANGUAGE_ENUM = {"enum": list(LANGUAGES)}
RunState = Literal[tuple(Run.State.values)]


class ProgramIn(Body):
    name: str = Field(min_length=1, max_length=100)
    language: str = Field(json_schema_extra=LANGUAGE_ENUM)
    source: str = ""
    origin: str = Field(
        "",
        description="where it came from, e.g. pushed from http://other:8000 by alice"
        " (one line, the first 300 characters kept)",
    )

    @field_validator("origin")
    @classmethod
    def one_line_origin(cls, value):
        return outbound.one_line(value) if value is not None else value

    @field_validator("language")
    @classmethod
    def known_language(cls, value):
        if value is None:  # ProgramUpdate: unchanged
            return value
        get_language(value)  # raises ValueError naming the known ones
        return value

    @field_validator("source")
    @classmethod
    def not_too_large(cls, value):
        if value is not None and len(value.encode()) > MAX_SOURCE_BYTES:
            raise ValueError(_("source larger than %(kb)s KB") % {"kb": MAX_SOURCE_BYTES // 1024})
        return value

    @field_validator("name")
    @classmethod
    def stripped(cls, value):
        if value is None:
            return value
        value = value.strip()
        if not value:
            raise ValueError(_("name must not be blank"))
        return names.check(value)  # as the pages' forms: after the spaces around it go


class ProgramUpdate(ProgramIn):
    name: str | None = Field(None, min_length=1, max_length=100)
    language: str | None = Field(None, json_schema_extra=LANGUAGE_ENUM)
    source: str | None = None

    @model_validator(mode="wrap")
    @classmethod
    def an_object(cls, value, handler):
        # Every field is optional: without this, a body of 0 or [] would be an empty update.
        if not isinstance(value, dict):
            raise ValueError(_("the body must be a JSON object"))
        return handler(value)


class ProgramOut(Schema):
    id: int
    name: str
    language: str
    source: str
    owner: str = Field(alias="owner.username")
    created: datetime
    updated: datetime
    revisions: int = Field(alias="revision_count")
    origin: str = ""


class RunIn(Body):
    robot: Name = Field(min_length=1)
    args: list[str] = []


class RunOut(Schema):
    id: int
    program: int | None = Field(alias="program_id")
    program_name: str
    language: str
    robot: str = Field(alias="robot.name")
    owner: str = Field(alias="owner.username")
    state: str
    queue_position: int | None = Field(
        None, description="while queued: its place in its robot's line, 1 for the next to start"
    )
    exit_code: int | None
    reason: str
    created: datetime
    started: datetime | None
    ended: datetime | None
    log_bytes: int = Field(
        0, description="the bytes its log takes on disk, counted against its owner's quota"
    )
    log_pruned_at: datetime | None = Field(
        None, description="when its log was deleted to keep run logs within a quota, if it was"
    )
    log_pruned_reason: str = Field("", description="why its log was deleted, if it was")

    live: str = Field(
        "",
        description="its live output: the path of a websocket sending HTML fragments; for a "
        "caller signed in with a session, with a pass that opens it at once for 2 s",
    )

    @staticmethod
    def resolve_queue_position(run: Run) -> int | None:
        return run.queue_rank

    @staticmethod
    def resolve_live(run: Run, context) -> str:
        return watch_pass.live_path(run, context["request"])


class QueueMoveIn(Body):
    position: int = Field(ge=1, description="its new place in line, 1-based (past the end: last)")


class QueueResumeIn(Body):
    robot: Name = Field(min_length=1)


class QueueResumedOut(Schema):
    robot: str
    waiting: int = Field(description="runs waiting in the queue that moves again")


class Error(Schema):
    detail: str


def _program_out(program: Program) -> Program:
    program.revision_count = program.revisions.count()
    return program


@programs_router.get("", response=list[ProgramOut])
def list_programs(request):
    return programs_for_user(request.user).annotate(revision_count=Count("revisions"))


@programs_router.post("", response={201: ProgramOut, 409: Error})
def create_program(request, data: ProgramIn):
    try:
        program = Program.objects.create(
            owner=request.user, name=data.name, language=data.language, origin=data.origin
        )
    except IntegrityError:
        return Status(409, {"detail": already_named(data.name)})
    program.save_source(data.source, request.user)
    return Status(201, _program_out(program))


@programs_router.get("/{int:program_id}", response=ProgramOut)
def get_program(request, program_id: int):
    return _program_out(get_program_for_user(request.user, program_id))


@programs_router.put("/{int:program_id}", response={200: ProgramOut, 409: Error})
def update_program(request, program_id: int, data: ProgramUpdate):
    program = get_program_for_user(request.user, program_id, EDIT)
    if data.name is not None and data.name != program.name:
        get_program_for_user(request.user, program_id, OWN)  # renaming: its owner's (403)
        program.name = data.name
    if data.language is not None:
        program.language = data.language
    try:
        program.save_source(program.source if data.source is None else data.source, request.user)
    except IntegrityError:
        return Status(409, {"detail": already_named(data.name)})
    return Status(200, _program_out(program))


@programs_router.delete("/{int:program_id}", response={204: None})
def delete_program(request, program_id: int):
    get_program_for_user(request.user, program_id, OWN).delete()
    return Status(204, None)


@programs_router.post("/{int:program_id}/run", response={201: RunOut, 409: Error, 503: Error})
def run_program(request, program_id: int, data: RunIn):
    program = get_program_for_user(request.user, program_id)
    robot = robot_to_run_on(request.user, data.robot)  # no robot open to them: 409 saying why
    return Status(201, start_run(program, robot, request.user, data.args))


class ImportedOut(Schema):
    id: int
    name: str
    file: str


class SkippedOut(Schema):
    file: str
    why: str


class ImportReportOut(Schema):
    created: list[ImportedOut]
    updated: list[ImportedOut]
    skipped: list[SkippedOut]


ZIP_RESPONSE = {
    "description": "The caller's own programs: one plain file each and manifest.json",
    "content": {"application/zip": {"schema": {"type": "string", "format": "binary"}}},
}
ARCHIVE_STATUS = {archive.NotAZip: 400, archive.ArchiveTooLarge: 413, archive.BadArchive: 422}


def _error_response(why: str, detail: dict) -> dict:
    schema = {"type": "object", "properties": {"detail": detail}, "required": ["detail"]}
    return {"description": why, "content": {"application/json": {"schema": schema}}}


# With string keys, as robotide.api adds the common errors: declared in response= too (int
# keys), each status would be in the schema's JSON twice.
IMPORT_RESPONSES = {
    "400": _error_response("Not a zip, or a damaged one", {"type": "string"}),
    "413": _error_response("Too many files or bytes", {"type": "string"}),
    "422": _error_response(
        "Unsafe or nested paths, a manifest not robotide's, or no file",
        {"anyOf": [{"type": "string"}, {"type": "array"}]},
    ),
}


@programs_router.get("/export", openapi_extra={"responses": {200: ZIP_RESPONSE}})
def export_programs(request):
    # Only the caller's own: staff see everyone's programs, but an export is one person's.
    data = archive.export_zip(Program.objects.filter(owner=request.user))
    response = HttpResponse(data, content_type="application/zip")
    filename = archive.export_filename(request.user)
    response["Content-Disposition"] = content_disposition_header(True, filename)
    return response


@programs_router.post(
    "/import", response=ImportReportOut, openapi_extra={"responses": IMPORT_RESPONSES}
)
def import_programs(request, file: File[UploadedFile], replace: Form[bool] = False):
    """A zip as made by export (or any zip of program files) becomes the caller's programs."""
    try:
        report = archive.import_zip(
            file.read(), request.user, filename=file.name or "a zip", replace=replace
        )
    except archive.ArchiveError as exc:
        raise HttpError(ARCHIVE_STATUS[type(exc)], str(exc)) from None
    return report.as_dict()


@programs_router.get("/languages", response=list[dict], auth=None)
def list_languages(request):
    return [
        {"name": lang.name, "label": str(lang.label), "extension": lang.extension,
         "available": lang.available, "install": lang.install_hint}
        for lang in LANGUAGES.values()
    ]  # fmt: skip


class EmailIn(Body):
    to: str = Field(min_length=1, max_length=320, description="one e-mail address")


class EmailOut(Schema):
    to: str
    attachment: str = Field(description="the attached file's name")


class PushIn(Body):
    url: str = Field(
        min_length=1,
        max_length=outbound.MAX_URL,
        description="the other robotide, http(s)://HOST:PORT",
    )
    token: str = Field(
        min_length=1,
        max_length=outbound.MAX_TOKEN,
        description="an API token of the account there that gets the program",
    )


class PushOut(Schema):
    url: str
    id: int | None = Field(description="the program's id there")
    name: str = Field(description='its name there: " (2)" added if the account had it already')
    owner: str


@programs_router.post(
    "/{int:program_id}/email",
    response={200: EmailOut, 429: Error, 502: Error, 503: Error},
)
def email_program(request, program_id: int, data: EmailIn):
    """Mail the program, its source attached, to one address (each user has
    ROBOTIDE_EMAIL_PER_HOUR mails an hour; 0 is 403, sending by e-mail turned off)."""
    program = get_program_for_user(request.user, program_id)
    site = outbound.site_of(request)
    try:
        to = outbound.email_program(program, data.to, user=request.user, site=site)
    except outbound.OutboundError as exc:
        raise HttpError(exc.status, str(exc)) from exc
    return {"to": to, "attachment": program.filename}


@programs_router.post(
    "/{int:program_id}/push", response={200: PushOut, 429: Error, 502: Error, 504: Error}
)
def push_program(request, program_id: int, data: PushIn):
    """Push the program to another robotide: it arrives there as a program of the token's
    account, its origin saying where it came from."""
    program = get_program_for_user(request.user, program_id)
    site = outbound.site_of(request)
    try:
        return outbound.push_program(program, data.url, data.token, user=request.user, site=site)
    except outbound.OutboundError as exc:
        raise HttpError(exc.status, str(exc)) from exc


@runs_router.get("", response=list[RunOut])
def list_runs(request, state: RunState | None = None, robot: Name | None = None, limit: int = 100):
    """Runs you may see; to staff and a robot's owner, also every run queued on it."""
    runs = run_queue.runs_to_see(request.user)
    if state is not None:
        runs = runs.filter(state=state)
    if robot is not None:
        runs = runs.filter(robot__name=robot)
    return runs[: max(1, min(limit, 1000))]


@runs_router.get("/{int:run_id}", response=RunOut)
def get_run(request, run_id: int):
    return run_queue.get_run_to_manage(request.user, run_id)


@runs_router.get("/{int:run_id}/log")
def get_run_log(request, run_id: int, stream: Literal["all", "stdout", "stderr"] = "all"):
    run = get_run_for_user(request.user, run_id)
    streams = {"all": "oes", "stdout": "o", "stderr": "e"}[stream]
    return download(run, streams)  # 410 saying when and why if its log was pruned


@runs_router.post("/{int:run_id}/stop", response=RunOut)
def stop_run(request, run_id: int):
    """Stop a run; a queued one is cancelled at once (``stopped``, "cancelled while queued"),
    also by staff or the robot's owner."""
    run = run_queue.get_run_to_manage(request.user, run_id)
    request_stop(run)
    return run


@runs_router.post("/{int:run_id}/queue", response={200: RunOut, 409: Error})
def move_in_queue(request, run_id: int, data: QueueMoveIn):
    """Staff or the robot's owner put a queued run at another place in its robot's line."""
    run = run_queue.get_run_to_manage(request.user, run_id)
    try:
        run_queue.move(request.user, run, data.position)
    except run_queue.NotQueued as exc:
        return Status(409, {"detail": str(exc)})
    run.refresh_from_db()
    return Status(200, run)


@runs_router.post("/queue/resume", response={200: QueueResumedOut, 404: Error})
def resume_queue(request, data: QueueResumeIn):
    """After an emergency stop held a robot's queue: staff or its owner let it move again,
    and the runs it held start as their turns come."""
    robot = get_robot_for_user(request.user, data.robot)
    waiting = stops.resume(request.user, robot, "the API", start_held=True)
    return {"robot": robot.name, "waiting": waiting}
