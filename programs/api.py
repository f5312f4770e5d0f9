from datetime import datetime
from typing import Literal

from django.db import IntegrityError
from django.db.models import Count
from django.http import HttpResponse, StreamingHttpResponse
from ninja import Field, Router, Schema
from ninja.responses import Status
from pydantic import field_validator, model_validator

from programs.access import get_program_for_user, get_run_for_user, programs_for_user, runs_for_user
from programs.languages import LANGUAGES, get_language
from programs.models import MAX_SOURCE_BYTES, Program, Run, request_stop, start_run
from programs.runlog import plain_text
from robots.models import get_robot_for_user

programs_router = Router(tags=["programs"])
runs_router = Router(tags=["runs"])

# The allowed values in the OpenAPI schema; the validators below give the clearer errors.
LANGUAGE_ENUM = {"enum": list(LANGUAGES)}
RunState = Literal[tuple(Run.State.values)]


class ProgramIn(Schema):
    name: str = Field(min_length=1, max_length=100)
    language: str = Field(json_schema_extra=LANGUAGE_ENUM)
    source: str = ""

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
            raise ValueError(f"source larger than {MAX_SOURCE_BYTES // 1024} KB")
        return value

    @field_validator("name")
    @classmethod
    def stripped(cls, value):
        if value is None:
            return value
        value = value.strip()
        if not value:
            raise ValueError("name must not be blank")
        return value


class ProgramUpdate(ProgramIn):
    name: str | None = Field(None, min_length=1, max_length=100)
    language: str | None = Field(None, json_schema_extra=LANGUAGE_ENUM)
    source: str | None = None

    @model_validator(mode="wrap")
    @classmethod
    def an_object(cls, value, handler):
        # Every field is optional: without this, a body of 0 or [] would be an empty update.
        if not isinstance(value, dict):
            raise ValueError("the body must be a JSON object")
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


class RunIn(Schema):
    robot: str = Field(min_length=1)
    args: list[str] = []


class RunOut(Schema):
    id: int
    program: int | None = Field(alias="program_id")
    program_name: str
    language: str
    robot: str = Field(alias="robot.name")
    owner: str = Field(alias="owner.username")
    state: str
    exit_code: int | None
    reason: str
    created: datetime
    started: datetime | None
    ended: datetime | None


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
        program = Program.objects.create(owner=request.user, name=data.name, language=data.language)
    except IntegrityError:
        return Status(409, {"detail": f"You already have a program named {data.name!r}."})
    program.save_source(data.source, request.user)
    return Status(201, _program_out(program))


@programs_router.get("/{int:program_id}", response=ProgramOut)
def get_program(request, program_id: int):
    return _program_out(get_program_for_user(request.user, program_id))


@programs_router.put("/{int:program_id}", response={200: ProgramOut, 409: Error})
def update_program(request, program_id: int, data: ProgramUpdate):
    program = get_program_for_user(request.user, program_id)
    if data.name is not None:
        program.name = data.name
    if data.language is not None:
        program.language = data.language
    try:
        program.save_source(program.source if data.source is None else data.source, request.user)
    except IntegrityError:
        return Status(409, {"detail": f"You already have a program named {data.name!r}."})
    return Status(200, _program_out(program))


@programs_router.delete("/{int:program_id}", response={204: None})
def delete_program(request, program_id: int):
    get_program_for_user(request.user, program_id).delete()
    return Status(204, None)


@programs_router.post("/{int:program_id}/run", response={201: RunOut, 409: Error, 503: Error})
def run_program(request, program_id: int, data: RunIn):
    program = get_program_for_user(request.user, program_id)
    robot = get_robot_for_user(request.user, data.robot)
    return Status(201, start_run(program, robot, request.user, data.args))


@programs_router.get("/languages", response=list[dict], auth=None)
def list_languages(request):
    return [
        {"name": lang.name, "label": lang.label, "extension": lang.extension,
         "available": lang.available, "install": lang.install_hint}
        for lang in LANGUAGES.values()
    ]  # fmt: skip


@runs_router.get("", response=list[RunOut])
def list_runs(request, state: RunState | None = None, robot: str | None = None, limit: int = 100):
    runs = runs_for_user(request.user)
    if state is not None:
        runs = runs.filter(state=state)
    if robot is not None:
        runs = runs.filter(robot__name=robot)
    return runs[: max(1, min(limit, 1000))]


@runs_router.get("/{int:run_id}", response=RunOut)
def get_run(request, run_id: int):
    return get_run_for_user(request.user, run_id)


@runs_router.get("/{int:run_id}/log")
def get_run_log(request, run_id: int, stream: Literal["all", "stdout", "stderr"] = "all"):
    run = get_run_for_user(request.user, run_id)
    streams = {"all": "oes", "stdout": "o", "stderr": "e"}[stream]
    if not run.log_path.exists():
        return HttpResponse(b"", content_type="text/plain; charset=utf-8")
    return StreamingHttpResponse(
        plain_text(run.log_path, streams), content_type="text/plain; charset=utf-8"
    )


@runs_router.post("/{int:run_id}/stop", response=RunOut)
def stop_run(request, run_id: int):
    run = get_run_for_user(request.user, run_id)
    request_stop(run)
    return run
