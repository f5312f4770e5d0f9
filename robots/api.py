import re

from django.db import IntegrityError
from django.utils.translation import gettext as _
from ninja import Field, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import field_validator, model_validator

import rhal
from programs.api import Error
from robotide.names import Name
from robotide.schemas import Body
from robots import disclosure, fair_shares, reset, say, stops
from robots.bus import announce_robot_sync, ask_agent_sync, reconfigure_sync
from robots.driver_settings import check_settings, known_driver
from robots.models import Robot, get_robot_for_user, robots_for_user

robots_router = Router(tags=["robots"])

# The known driver schemes in the OpenAPI schema; `known_driver` gives the clearer error.
DRIVER_URL = {"pattern": f"^({'|'.join(re.escape(scheme) for scheme in sorted(rhal.DRIVERS))})://"}


class RobotIn(Body):
    name: Name = Field(pattern=r"^[a-zA-Z0-9_-]{1,50}$")
    url: str = Field(min_length=1, max_length=500, json_schema_extra=DRIVER_URL)
    settings: dict = {}
    description: str = ""

    @field_validator("url")
    @classmethod
    def known_driver(cls, value):
        return known_driver(value)

    @model_validator(mode="after")
    def usable_settings(self):
        check_settings(self.url, self.settings)
        return self


class RobotPatch(Body):
    url: str | None = Field(None, min_length=1, max_length=500, json_schema_extra=DRIVER_URL)
    settings: dict | None = None
    description: str | None = Field(None, max_length=200)


class RobotOut(Schema):
    name: str
    url: str = Field(
        description="its driver URL for its owner and staff (a password masked); its driver"
        " alone for others, e.g. pioneer://"
    )
    settings: dict = Field(description="for its owner and staff; {} for others")
    description: str
    online: bool = Field(description="its agent sent a heartbeat within the last few seconds")
    last_seen: str | None = Field(None, description="its agent's last heartbeat")
    agent_host: str = Field("", description="where its agent runs")
    isolation: str = Field(
        description="What its agent gives each run, or why runs are refused, for its owner and"
        " staff; one plain sentence for others"
    )
    # Fair shares in force (robots.fair_shares); more runs wait queued, saying why.
    runs_per_user: int | None = Field(
        None, description="runs you may have going at once, on all robots; null: no limit"
    )
    your_runs_going: int = Field(0, description="your runs going now, on all robots")
    runs_at_once: int | None = Field(
        None, description="runs this robot has going at once, whoever's; null: no limit"
    )
    runs_going: int = Field(0, description="runs going on this robot now")
    personal: bool = Field(
        False, description="a personal sim (/api/sims): its owner's alone, with their teachers"
    )
    twin_of: str = Field(
        "", description="a personal sim's: the robot whose speeds and sensors it has"
    )

    @staticmethod
    def resolve_url(robot, context):
        return disclosure.url_shown(context["request"].user, robot)

    @staticmethod
    def resolve_settings(robot, context):
        return disclosure.settings_shown(context["request"].user, robot)

    @staticmethod
    def resolve_isolation(robot, context):
        return disclosure.isolation_api(context["request"].user, robot)

    @staticmethod
    def resolve_last_seen(robot):
        return robot.last_seen.isoformat() if robot.last_seen else None

    @staticmethod
    def resolve_runs_per_user(robot, context):
        return fair_shares.in_force_of(context["request"].user, robot).runs_per_user

    @staticmethod
    def resolve_your_runs_going(robot, context):
        return fair_shares.in_force_of(context["request"].user, robot).yours_going

    @staticmethod
    def resolve_runs_at_once(robot, context):
        return fair_shares.in_force_of(context["request"].user, robot).runs_at_once

    @staticmethod
    def resolve_runs_going(robot, context):
        return fair_shares.in_force_of(context["request"].user, robot).robot_going


@robots_router.get("", response=list[RobotOut])
def list_robots(request):
    return robots_for_user(request.user)


@robots_router.post("", response={201: RobotOut, 409: dict})
def create_robot(request, data: RobotIn):
    if not request.user.is_staff:
        raise HttpError(403, _("Only staff may add robots."))
    try:
        robot = Robot.objects.create(**data.dict(), owner=request.user)
    except IntegrityError:
        detail = _("A robot named %(name)s exists already.") % {"name": repr(data.name)}
        return Status(409, {"detail": detail})
    announce_robot_sync(robot.name)
    return Status(201, robot)


@robots_router.get("/{name}", response=RobotOut)
def get_robot(request, name: Name):
    return get_robot_for_user(request.user, name)


@robots_router.patch("/{name}", response=RobotOut)
def update_robot(request, name: Name, data: RobotPatch):
    """Change a robot's URL, settings or description; its agent reopens the robot with them."""
    if not request.user.is_staff:
        raise HttpError(403, _("Only staff may change robots."))
    robot = get_robot_for_user(request.user, name)
    changes = data.dict(exclude_none=True)
    url, settings = changes.get("url", robot.url), changes.get("settings", robot.settings)
    try:
        known_driver(url)
        check_settings(url, settings)
    except ValueError as exc:  # as ninja's own validation errors: 422
        raise HttpError(422, str(exc)) from None
    for field, value in changes.items():
        setattr(robot, field, value)
    robot.save()
    reconfigure_sync(robot.name)
    return robot


@robots_router.get("/{name}/sensors", response={200: dict, 503: Error})
def robot_sensors(request, name: Name):
    robot = get_robot_for_user(request.user, name)
    return ask_agent_sync(robot.name, "robot.sensors")["sensors"]


@robots_router.post("/{name}/estop", response={200: dict, 503: Error})
def robot_estop(request, name: Name):
    """The emergency stop: the robot's own stop, every run on it killed at once, and nothing
    moves it until it is resumed. Recorded (who, when, the runs it ended)."""
    robot = get_robot_for_user(request.user, name)
    record = stops.press(request.user, robot, "the API")
    return {"robot": robot.name, "stopped_runs": len(record.runs), "runs": record.runs}


@robots_router.post("/{name}/resume", response={200: dict})
def robot_resume(request, name: Name, start_held: bool = False):
    """After an emergency stop: staff, the robot's owner or whoever pressed it (alone).
    ``waiting``: the runs it held; they stay queued, held, until started again, unless
    ``?start_held=true``."""
    robot = get_robot_for_user(request.user, name)
    waiting = stops.resume(request.user, robot, "the API", start_held=start_held)
    return {"robot": robot.name, "waiting": waiting}


class HearIn(Body):
    text: str = Field(
        min_length=1, max_length=200, description="what the robot hears, as if it was said"
    )
    queue: bool = Field(
        True,
        description="false: only if a program's listen() waits now (409 else); true: else it"
        " waits up to 10 s for the next listen()",
    )


class HeardOut(Schema):
    robot: str
    text: str
    listening: bool = Field(
        description="a program's listen() was waiting and heard it; false: it waits for the next"
    )


@robots_router.post("/{name}/hear", response={200: HeardOut, 409: Error, 503: Error})
def robot_hear(request, name: Name, data: HearIn):
    """Say something to the robot's programs, as its page's "Say to the robot" box does: what
    their listen() hears (on the sim, typed phrases are all it hears). Whoever may drive it."""
    robot = get_robot_for_user(request.user, name)
    if not say.may_say(request.user, robot):
        raise HttpError(403, say.not_yours(robot))
    try:
        listening = say.say_sync(robot, request.user, data.text, data.queue)
    except say.SayRefused as exc:
        return Status(409, {"detail": str(exc)})
    return {"robot": robot.name, "text": data.text, "listening": listening}


class PoseIn(Body):
    x: float | None = Field(None, allow_inf_nan=False, description="m east of the arena's centre")
    y: float | None = Field(None, allow_inf_nan=False, description="m north of the arena's centre")
    theta: float | None = Field(
        None, allow_inf_nan=False, description="rad, counter-clockwise from east"
    )

    @model_validator(mode="after")
    def all_or_none(self):
        given = [value is not None for value in (self.x, self.y, self.theta)]
        if any(given) and not all(given):
            raise ValueError(_("give x, y and theta, all three or none"))
        return self

    def pose(self) -> tuple[float, float, float] | None:
        return None if self.x is None else (self.x, self.y, self.theta)


class ResetOut(Schema):
    robot: str
    pose: list[float] | None = Field(
        description="[x, y, theta] it was put at, where the next run starts; null: the world's"
        " start pose"
    )


@robots_router.post("/{name}/reset", response={200: ResetOut, 409: Error, 503: Error})
def robot_reset(request, name: Name, data: PoseIn | None = None):
    """A simulated robot back at its world's start pose, or at the pose given (where the next
    run starts, whatever its start_each_run setting says): stopped, with a fresh odometer,
    battery and path. Whoever may drive it; while someone else's run goes on it, its owner and
    staff only (409 else). 409 for a robot that cannot be reset (a real one), 422 for a pose
    outside its world or on something."""
    robot = get_robot_for_user(request.user, name)
    if not reset.may_reset(request.user, robot):
        raise HttpError(403, reset.not_yours(robot))
    pose = data.pose() if data is not None else None
    try:
        reset.reset_sync(robot, request.user, pose)
    except reset.ResetRefused as exc:
        if exc.status == 422:  # as ninja's own validation errors
            raise HttpError(422, str(exc)) from None
        return Status(409, {"detail": str(exc)})
    return {"robot": robot.name, "pose": list(pose) if pose is not None else None}
