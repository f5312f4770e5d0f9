"""The Robot API methods a program may call, bound to the agent that launched it."""

import asyncio
import json
import math
import time

import rhal
from robots.host_services import HostServices
from robots.lease import Holder, LeaseHeld
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
MAX_MESSAGE_BYTES = 64 * 1024
MAX_QUEUED = 1000  # values a subscriber may have waiting
MAX_MEMORY_KEYS = 1000


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
            "publish": self.publish,
            "subscribe": self.subscribe,
            "receive": self.receive,
            "memory_set": self.memory_set,
            "memory_get": self.memory_get,
        }
        # The paper's phone services: speech, the camera, barcodes, listening.
        self.methods.update(HostServices(agent).methods)
        self.topics: dict[str, set[asyncio.Queue]] = {}
        self.memory: dict[str, object] = {}

    def quick(self, method: str) -> bool:
        """Methods that need no task of their own: those that ask the driver nothing it must
        wait for, on a driver that says its answers come at once (the sim robot)."""
        if method in ("auth", "capabilities", "show", "publish", "subscribe", "memory_set",
                      "memory_get"):  # fmt: skip
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
            if handler in (self.subscribe, self.receive):  # these belong to the connection
                return await handler(active, params, session=session)
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
        try:
            self.agent.take_lease(Holder("run", active.run_id, active.user))
        except LeaseHeld as exc:
            raise RpcError(ROBOT_ERROR, str(exc)) from None
        applied = await self.agent.driver.drive(linear, 0.0 if angular is None else angular)
        self.agent.motion_owner = active.run_id
        return applied

    async def stop(self, active, params):
        bind_params(params, (), 0)
        # Without control of the robot, a program has no motion to stop: the motors stay
        # with whoever controls them (stopping is never an error).
        if self.agent.lease.holder is None or self.agent.lease.holds(active.run_id):
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
            self.make_room(shows)
        shows[name] = self.changed_shows[name] = entry
        return None

    def make_room(self, shows: dict) -> None:
        """Values stay on the robot's page after their program ends, until the room is needed:
        then the oldest value of an ended run goes."""
        ended = [(e["time"], n) for n, e in shows.items() if e["run"] not in self.agent.runs]
        if not ended:
            raise ValueError(f"at most {MAX_SHOWS} values shown at once per robot")
        name = min(ended)[1]
        del shows[name]
        self.agent._shows_snapshot_due = True  # the page drops it too

    # -- programs that cooperate: messages by topic, and a small shared memory ----------------

    async def publish(self, active, params):
        topic, value = bind_params(params, ("topic", "value"), 2)
        check_name("topic", topic)
        check_size(value)
        queues = self.topics.get(topic, ())
        for queue in queues:
            if queue.full():  # a subscriber that does not keep up loses its oldest
                queue.get_nowait()
            queue.put_nowait(value)
        return len(queues)

    async def subscribe(self, active, params, session=None):
        (topic,) = bind_params(params, ("topic",), 1)
        check_name("topic", topic)
        if topic not in session.subscriptions:
            queue = asyncio.Queue(MAX_QUEUED)
            session.subscriptions[topic] = queue
            self.topics.setdefault(topic, set()).add(queue)
        return None

    async def receive(self, active, params, session=None):
        topic, timeout = bind_params(params, ("topic", "timeout"), 1)
        queue = session.subscriptions.get(topic)
        if queue is None:
            raise ValueError(f"subscribe to {topic!r} before receiving from it")
        if timeout is not None and (
            isinstance(timeout, bool) or not isinstance(timeout, int | float) or timeout < 0
        ):
            raise ValueError("timeout must be a number of seconds, or null to wait for ever")
        try:
            return await asyncio.wait_for(queue.get(), timeout)
        except TimeoutError:
            return None

    def forget(self, session) -> None:
        """A connection gone: its subscriptions with it."""
        for topic, queue in session.subscriptions.items():
            queues = self.topics.get(topic)
            if queues is not None:
                queues.discard(queue)
                if not queues:
                    del self.topics[topic]

    async def memory_set(self, active, params):
        key, value = bind_params(params, ("key", "value"), 2)
        check_name("key", key)
        check_size(value)
        if key not in self.memory and len(self.memory) >= MAX_MEMORY_KEYS:
            raise ValueError(f"the shared memory holds at most {MAX_MEMORY_KEYS} keys")
        self.memory[key] = value
        return None

    async def memory_get(self, active, params):
        (key,) = bind_params(params, ("key",), 1)
        check_name("key", key)
        return self.memory.get(key)


def check_name(what: str, name) -> None:
    if not isinstance(name, str) or not 0 < len(name) <= MAX_SHOW_NAME:
        raise ValueError(f"{what} must be a text of 1 to {MAX_SHOW_NAME} characters")


def check_size(value) -> None:
    if len(json.dumps(value)) > MAX_MESSAGE_BYTES:
        raise ValueError(f"value larger than {MAX_MESSAGE_BYTES // 1024} KB")


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
