"""The Robot API methods a program may call, bound to the agent that launched it."""

import math
import time

import rhal
from robots.rpc import (
    INVALID_PARAMS,
    METHOD_NOT_FOUND,
    ROBOT_ERROR,
    UNAUTHORIZED,
    RpcError,
    Session,
    bind_params,
)

MAX_SHOW_NAME = 64
MAX_SHOW_BYTES = 256 * 1024
MAX_SHOWS = 64


class RobotApi:
    def __init__(self, agent):
        self.agent = agent
        self.changed_shows: dict[str, dict] = {}
        self.methods = {
            "drive": self.drive,
            "stop": self.stop,
            "sensors": self.sensors,
            "sensor": self.sensor,
            "capabilities": self.capabilities,
            "show": self.show,
        }

    def quick(self, method: str) -> bool:
        """Methods that need no task of their own: those that ask the driver nothing it must
        wait for, on a driver that says its answers come at once (the sim robot)."""
        if method in ("auth", "capabilities", "show"):
            return True
        return method in ("sensors", "sensor", "drive", "stop") and self.agent.driver.quick

    async def handle(self, session: Session, method: str, params):
        if method == "auth":
            return self.auth(session, params)
        active = session.run
        if active is None:
            raise RpcError(UNAUTHORIZED, "not authenticated: call auth with $ROBOT_TOKEN first")
        if self.agent.tokens.get(active.token) is not active:
            raise RpcError(UNAUTHORIZED, "this run has ended: its token is no longer valid")
        handler = self.methods.get(method)
        if handler is None:
            known = ", ".join(sorted(self.methods))
            raise RpcError(METHOD_NOT_FOUND, f"no method {method!r}; methods: {known}")
        try:
            return await handler(active, params)
        except rhal.NotSupportedError as exc:
            raise RpcError(ROBOT_ERROR, str(exc)) from None
        except rhal.RhalError as exc:
            raise RpcError(ROBOT_ERROR, f"robot error: {exc}") from None
        except ValueError as exc:
            raise RpcError(INVALID_PARAMS, str(exc)) from None

    def auth(self, session: Session, params):
        (token,) = bind_params(params, ("token",), 1)
        active = self.agent.tokens.get(token) if isinstance(token, str) else None
        if active is None:
            raise RpcError(UNAUTHORIZED, "invalid token: it belongs to no running program")
        session.run = active
        return {"robot": self.agent.name, "run": active.run_id}

    async def drive(self, active, params):
        linear, angular = bind_params(params, ("linear", "angular"), 1)
        applied = await self.agent.driver.drive(linear, 0.0 if angular is None else angular)
        self.agent.motion_owner = active.run_id
        return applied

    async def stop(self, active, params):
        bind_params(params, (), 0)
        await self.agent.driver.stop()
        return None

    async def sensors(self, active, params):
        bind_params(params, (), 0)
        return await self.agent.driver.sensors()

    async def sensor(self, active, params):
        (name,) = bind_params(params, ("name",), 1)
        if not isinstance(name, str):
            raise ValueError("sensor name must be a string")
        return await self.agent.driver.sensor(name)

    async def capabilities(self, active, params):
        bind_params(params, (), 0)
        return self.agent.driver.capabilities()

    async def show(self, active, params):
        name, value = bind_params(params, ("name", "value"), 2)
        entry = {"value": check_show_value(name, value), "run": active.run_id, "time": time.time()}
        shows = self.agent.shows
        if name not in shows and len(shows) >= MAX_SHOWS:
            raise ValueError(f"at most {MAX_SHOWS} shown values per robot")
        shows[name] = self.changed_shows[name] = entry
        return None


def check_show_value(name, value):
    if not isinstance(name, str) or not 0 < len(name) <= MAX_SHOW_NAME:
        raise ValueError(f"show name must be a text of 1 to {MAX_SHOW_NAME} characters")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError("show value must be a finite number")
    if value is None or isinstance(value, bool | int | float):
        return value
    if isinstance(value, str):
        if len(value.encode()) > MAX_SHOW_BYTES:
            raise ValueError(f"show value larger than {MAX_SHOW_BYTES // 1024} KB")
        return value
    raise ValueError("show value must be a number, a text or an SVG drawing (a text)")
