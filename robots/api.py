import re
from urllib.parse import urlsplit

from django.conf import settings as django_settings
from django.db import IntegrityError
from ninja import Field, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import field_validator, model_validator

import rhal
from programs.api import Error
from programs.isolation import IsolationUnavailable, Policy
from programs.launcher import Limits
from robots.bus import announce_robot_sync, ask_agent_sync
from robots.models import Robot, get_robot_for_user, robots_for_user

robots_router = Router(tags=["robots"])

# The known driver schemes in the OpenAPI schema; `known_driver` gives the clearer error.
DRIVER_URL = {"pattern": f"^({'|'.join(re.escape(scheme) for scheme in sorted(rhal.DRIVERS))})://"}


class RobotIn(Schema):
    name: str = Field(pattern=r"^[a-zA-Z0-9_-]{1,50}$")
    url: str = Field(min_length=1, max_length=500, json_schema_extra=DRIVER_URL)
    settings: dict = {}
    description: str = ""

    @field_validator("url")
    @classmethod
    def known_driver(cls, value):
        scheme = urlsplit(value).scheme.lower()
        if scheme not in rhal.DRIVERS:
            known = ", ".join(f"{name}://" for name in sorted(rhal.DRIVERS))
            raise ValueError(f"no robot driver for {value!r}; known: {known}")
        return value

    @model_validator(mode="after")
    def usable_settings(self):
        """Settings a robot's agent could not use are refused now, not found out later."""
        robot = Robot(name=self.name, url=self.url, settings=self.settings)
        try:
            Limits.from_settings(self.settings.get("limits", {}))
            Policy.from_settings(robot.run_isolation(django_settings.RUN_ISOLATION))
            rhal.connect(self.url, **robot.driver_options())  # builds it, opens nothing
        except (TypeError, ValueError, AttributeError, rhal.RhalError) as exc:
            raise ValueError(f"settings: {exc}") from None
        except IsolationUnavailable as exc:
            raise ValueError(f"settings: {exc}") from None
        return self


class RobotOut(Schema):
    name: str
    url: str
    settings: dict
    description: str
    last_seen: str | None = None
    isolation: str = Field(description="What its agent gives each run, or why runs are refused")

    @staticmethod
    def resolve_last_seen(robot):
        return robot.last_seen.isoformat() if robot.last_seen else None


@robots_router.get("", response=list[RobotOut])
def list_robots(request):
    return robots_for_user(request.user)


@robots_router.post("", response={201: RobotOut, 409: dict})
def create_robot(request, data: RobotIn):
    if not request.user.is_staff:
        raise HttpError(403, "Only staff may add robots.")
    try:
        robot = Robot.objects.create(**data.dict())
    except IntegrityError:
        return Status(409, {"detail": f"A robot named {data.name!r} exists already."})
    announce_robot_sync(robot.name)
    return Status(201, robot)


@robots_router.get("/{name}", response=RobotOut)
def get_robot(request, name: str):
    return get_robot_for_user(request.user, name)


@robots_router.get("/{name}/sensors", response={200: dict, 503: Error})
def robot_sensors(request, name: str):
    robot = get_robot_for_user(request.user, name)
    return ask_agent_sync(robot.name, "robot.sensors")["sensors"]


@robots_router.post("/{name}/estop", response={200: dict, 503: Error})
def robot_estop(request, name: str):
    robot = get_robot_for_user(request.user, name)
    reply = ask_agent_sync(robot.name, "robot.estop")
    return {"robot": robot.name, "stopped_runs": reply["stopped"]}
