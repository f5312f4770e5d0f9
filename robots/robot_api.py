"""The Robot API methods a program may call, bound to the agent that launched it."""

import asyncio
import json
import math
import time
from collections import deque

import rhal
from robots import debugger
from robots.host_services import HostServices
from robots.lease import Holder, LeaseHeld
from robots.rpc import (
    INVALID_PARAMS,
    INVALID_REQUEST,
    LIMIT_REACHED,
    METHOD_NOT_FOUND,
    ROBOT_ERROR,
    UNAUTHORIZED,
    RpcError,
    Session,
    bind_params,
)

KB, MB = 1024, 1024 * 1024

# What one run, and all runs together, may make the agent hold (PROTOCOL.md, "Limits"). A value
# is held as its JSON text and counts its length plus OVERHEAD bytes (what Python spends on
# keeping it), so a flood of tiny values is bounded as well as one of big ones.
OVERHEAD = 64

MAX_SHOW_NAME = 64
MAX_SHOW_BYTES = 256 * KB  # one shown value
MAX_SHOWS = 64  # values shown at once per robot
MAX_SHOWS_BYTES_RUN = 2 * MB  # all the values one run shows
MAX_SHOWS_BYTES = 4 * MB  # all the values shown on the robot's page

MAX_MESSAGE_BYTES = 64 * KB  # one published value, one value in the shared memory
MAX_SUBSCRIPTIONS = 64  # topics per connection
MAX_SUBSCRIPTIONS_RUN = 256  # over all of a run's connections
MAX_SUBSCRIPTIONS_ROBOT = 1024  # over all runs
MAX_QUEUED = 1000  # values a subscription may have waiting
MAX_QUEUED_BYTES = 4 * MB  # waiting in one subscription
MAX_QUEUED_BYTES_CONNECTION = 8 * MB  # waiting in all of one connection's subscriptions
MAX_QUEUED_BYTES_RUN = 16 * MB  # waiting for one run, over all its connections
MAX_QUEUED_BYTES_ROBOT = 64 * MB  # waiting for all the robot's runs

MAX_MEMORY_KEYS = 1000  # in the robot's shared memory
MAX_MEMORY_KEYS_RUN = 500  # last set by one run
MAX_MEMORY_BYTES = 8 * MB  # keys and values in the shared memory
MAX_MEMORY_BYTES_RUN = 4 * MB  # keys and values last set by one run

_encode = json.JSONEncoder(separators=(",", ":"), check_circular=False).encode


class LimitReached(RpcError, ValueError):
    """A cap reached (-32002); a ValueError too, for callers that treat it as bad input."""

    def __init__(self, message: str):
        super().__init__(LIMIT_REACHED, message)


class Subscription:
    """One connection's subscription to a topic: the values published since, oldest first,
    as JSON texts, and how many were dropped to keep within the limits."""

    __slots__ = ("topic", "session", "run_id", "values", "bytes", "dropped", "waiter")

    def __init__(self, topic: str, session: Session, run_id: int):
        self.topic, self.session, self.run_id = topic, session, run_id
        self.values: deque[str] = deque()
        self.bytes = 0
        self.dropped = 0  # since its subscriber last heard of it
        self.waiter: asyncio.Future | None = None  # a receive waiting for a value


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
        # These belong to the connection: they are given its session.
        self.per_connection = {self.subscribe, self.receive, *debugger.METHODS.values()}
        # The paper's phone services: speech, the camera, barcodes, listening; and its
        # `handlers` (robot.hear: a phrase typed for listen()) the agent's to dispatch.
        self.host = HostServices(agent)
        self.methods.update(self.host.methods)
        self.topics: dict[str, dict[Subscription, None]] = {}  # in subscription order
        self.queued = 0  # bytes waiting in all subscriptions
        self.queued_by_run: dict[int, int] = {}
        self.subscriptions = 0
        self.subscriptions_by_run: dict[int, int] = {}
        self.memory = SharedMemory(running=lambda run: run in self.agent.runs)
        self.show_costs: dict[str, tuple[int, int]] = {}  # shown name -> (run, bytes)

    def quick(self, method: str) -> bool:
        """Methods that need no task of their own: those that ask the driver nothing it must
        wait for, on a driver that says its answers come at once (the sim robot)."""
        if method in ("auth", "capabilities", "show", "publish", "subscribe", "memory_set",
                      "memory_get"):  # fmt: skip
            return True
        return method in ("sensors", "sensor", "drive", "stop") and self.agent.driver.quick

    async def handle(self, session: Session, method: str, params):
        if method == "auth":
            return await self.auth(session, params)
        active = session.run
        if active is None:
            raise RpcError(UNAUTHORIZED, "not authenticated: call auth with $ROBOT_TOKEN first")
        if self.agent.tokens.get(active.token) is not active:
            raise RpcError(UNAUTHORIZED, "this run has ended: its token is no longer valid")
        # The debugger's (robots.debugger) are not the programs' API (programs.robot_api_spec):
        # a run's debugger calls them, answered -32000 for a run not under the debugger.
        handler = self.methods.get(method) or debugger.METHODS.get(method)
        if handler is None:
            known = ", ".join(sorted(self.methods))
            raise RpcError(METHOD_NOT_FOUND, f"no method {method!r}; methods: {known}")
        try:
            if handler in self.per_connection:
                return await handler(active, params, session=session)
            return await handler(active, params)
        except RpcError:
            raise
        except rhal.NotSupportedError as exc:
            raise RpcError(ROBOT_ERROR, str(exc)) from None
        except rhal.RhalError as exc:
            raise RpcError(ROBOT_ERROR, f"robot error: {exc}") from None
        except ValueError as exc:
            raise RpcError(INVALID_PARAMS, str(exc)) from None

    async def auth(self, session: Session, params):
        (token,) = bind_params(params, ("token",), 1)
        active = self.agent.tokens.get(token) if isinstance(token, str) else None
        # A program may call at once: its run's claim may still be on its way (answered
        # straight from data_received once it has come, as every quick method).
        if active is None or not await active.confirmed():
            raise RpcError(UNAUTHORIZED, "invalid token: it belongs to no running program")
        if session.run is not None:  # its subscriptions and caps are that run's
            raise RpcError(INVALID_REQUEST, "this connection is signed in already")
        session.run = active
        active.signed_in()  # a check run's trace begins here (robots.check_sims)
        return {"robot": self.agent.name, "run": active.run_id}

    async def drive(self, active, params):
        linear, angular = bind_params(params, ("linear", "angular"), 1)
        if active.process is not None and active.process.stop_requested:  # after Stop
            raise RpcError(ROBOT_ERROR, "this program was asked to stop: it may not drive")
        paused = getattr(active, "debugger", None)
        if paused is not None and paused.paused:  # a pause is a motion stop
            raise RpcError(ROBOT_ERROR, debugger.PAUSED_HERE)
        holder = Holder("run", active.run_id, active.user)
        try:
            applied = await self.agent.drive_for(
                holder, linear, 0.0 if angular is None else angular
            )
        except LeaseHeld as exc:
            raise RpcError(ROBOT_ERROR, str(exc)) from None
        if paused is not None and paused.paused:  # paused while it was on its way
            await self.agent.stop_motion_of(active.run_id)
            raise RpcError(ROBOT_ERROR, debugger.PAUSED_HERE)
        if paused is not None:  # what a pause stops, and Continue gives back
            paused.moved(linear, 0.0 if angular is None else angular)
        return applied

    async def stop(self, active, params):
        bind_params(params, (), 0)
        # Without control of the robot, a program has no motion to stop: the motors stay
        # with whoever controls them (stopping is never an error).
        if self.agent.lease.holder is None or self.agent.lease.holds(active.run_id):
            await self.agent.driver.stop()
        if (debugged := getattr(active, "debugger", None)) is not None:
            debugged.stopped()
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
        shows, costs = self.agent.shows, self.show_costs
        cost = len(name) + (len(value) if isinstance(value, str) else 8) + OVERHEAD
        before = costs.get(name, (None, 0))
        run_total = sum(c for r, c in costs.values() if r == active.run_id)
        if before[0] == active.run_id:
            run_total -= before[1]
        if run_total + cost > MAX_SHOWS_BYTES_RUN:
            raise LimitReached(
                f"a run shows at most {MAX_SHOWS_BYTES_RUN // MB} MB of values: show fewer or"
                " smaller ones, or show them again under the same names",
            )
        while (name not in shows and len(shows) >= MAX_SHOWS) or (
            self.shows_bytes() - before[1] + cost > MAX_SHOWS_BYTES
        ):
            self.make_room(shows, keep=name)
        shows[name] = self.changed_shows[name] = entry
        costs[name] = (active.run_id, cost)
        return None

    def shows_bytes(self) -> int:
        return sum(c for _, c in self.show_costs.values())

    def make_room(self, shows: dict, keep: str = "") -> None:
        """Values stay on the robot's page after their program ends, until the room is needed:
        then the oldest value of an ended run goes."""
        for gone in set(self.show_costs) - set(shows):  # taken off the page elsewhere
            del self.show_costs[gone]
        running = self.agent.runs
        ended = [(e["time"], n) for n, e in shows.items() if e["run"] not in running and n != keep]
        if not ended:
            raise LimitReached(
                f"at most {MAX_SHOWS} values, {MAX_SHOWS_BYTES // MB} MB in all, shown at once"
                " per robot, and the robot's running programs show that much already",
            )
        name = min(ended)[1]
        del shows[name]
        self.show_costs.pop(name, None)
        self.agent._shows_snapshot_due = True  # the page drops it too

    # -- programs that cooperate: messages by topic, and a small shared memory ----------------

    async def publish(self, active, params):
        topic, value = bind_params(params, ("topic", "value"), 2)
        check_name("topic", topic)
        text = encode_value(value)
        cost = len(text) + OVERHEAD
        reached = 0
        for subscription in self.topics.get(topic, ()):
            reached += self.deliver(subscription, text, cost)
        return reached

    def deliver(self, sub: Subscription, text: str, cost: int) -> bool:
        """Queue a value for a subscriber; what does not fit its limits makes room by dropping
        its oldest values, each counted (receive says so). False if even that left no room
        (others of its run or robot hold the budget): then the new value is the one dropped."""
        session, run = sub.session, sub.run_id
        values = sub.values
        while values and (
            len(values) >= MAX_QUEUED
            or sub.bytes + cost > MAX_QUEUED_BYTES
            or session.queued + cost > MAX_QUEUED_BYTES_CONNECTION
            or self.queued_by_run.get(run, 0) + cost > MAX_QUEUED_BYTES_RUN
            or self.queued + cost > MAX_QUEUED_BYTES_ROBOT
        ):
            self._account(sub, -(len(values.popleft()) + OVERHEAD))
            sub.dropped += 1
        if (
            session.queued + cost > MAX_QUEUED_BYTES_CONNECTION
            or self.queued_by_run.get(run, 0) + cost > MAX_QUEUED_BYTES_RUN
            or self.queued + cost > MAX_QUEUED_BYTES_ROBOT
        ):
            sub.dropped += 1
            return False
        values.append(text)
        self._account(sub, cost)
        if sub.waiter is not None and not sub.waiter.done():
            sub.waiter.set_result(None)
        return True

    def _account(self, sub: Subscription, change: int) -> None:
        sub.bytes += change
        sub.session.queued += change
        self.queued += change
        self.queued_by_run[sub.run_id] = self.queued_by_run.get(sub.run_id, 0) + change

    async def subscribe(self, active, params, session=None):
        (topic,) = bind_params(params, ("topic",), 1)
        check_name("topic", topic)
        if topic in session.subscriptions:
            return None
        run = active.run_id
        for count, limit, of in (
            (len(session.subscriptions), MAX_SUBSCRIPTIONS, "a connection"),
            (self.subscriptions_by_run.get(run, 0), MAX_SUBSCRIPTIONS_RUN, "a run"),
            (self.subscriptions, MAX_SUBSCRIPTIONS_ROBOT, "the robot's runs together"),
        ):
            if count >= limit:
                raise LimitReached(f"{of} may subscribe to at most {limit} topics")
        subscription = Subscription(topic, session, run)
        session.subscriptions[topic] = subscription
        self.topics.setdefault(topic, {})[subscription] = None
        self.subscriptions += 1
        self.subscriptions_by_run[run] = self.subscriptions_by_run.get(run, 0) + 1
        self.queued_by_run.setdefault(run, 0)
        return None

    async def receive(self, active, params, session=None):
        topic, timeout, details = bind_params(params, ("topic", "timeout", "details"), 1)
        sub = session.subscriptions.get(topic)
        if sub is None:
            raise ValueError(f"subscribe to {topic!r} before receiving from it")
        if timeout is not None and (
            isinstance(timeout, bool) or not isinstance(timeout, int | float)
            or not math.isfinite(timeout) or timeout < 0
        ):  # fmt: skip
            raise ValueError("timeout must be a number of seconds, or null to wait for ever")
        if details is not None and not isinstance(details, bool):
            raise ValueError("details must be true or false")
        if not sub.values and timeout != 0:
            sub.waiter = asyncio.get_running_loop().create_future()
            try:
                await asyncio.wait_for(sub.waiter, timeout)
            except TimeoutError:
                pass
            finally:
                sub.waiter = None
        value = None
        if sub.values:
            text = sub.values.popleft()
            self._account(sub, -(len(text) + OVERHEAD))
            value = json.loads(text)
        if not details:
            return value
        dropped, sub.dropped = sub.dropped, 0
        return {"value": value, "dropped": dropped, "waiting": len(sub.values)}

    def forget(self, session) -> None:
        """A connection gone: its subscriptions with it, and what waited in them (a
        debugger's waits too)."""
        paused = getattr(session.run, "debugger", None)
        if paused is not None:
            paused.forget(session)
        subscriptions, session.subscriptions = session.subscriptions, {}
        for topic, sub in subscriptions.items():
            if sub.waiter is not None and not sub.waiter.done():
                sub.waiter.cancel()  # its receive ends now, not as a task left pending
            subs = self.topics.get(topic)
            if subs is not None:
                subs.pop(sub, None)
                if not subs:
                    del self.topics[topic]
            if sub.bytes:
                self._account(sub, -sub.bytes)
            sub.values.clear()
            run = sub.run_id
            self.subscriptions -= 1
            left = self.subscriptions_by_run[run] = self.subscriptions_by_run[run] - 1
            if not left:
                del self.subscriptions_by_run[run]
                if not self.queued_by_run.get(run):
                    self.queued_by_run.pop(run, None)

    async def memory_set(self, active, params):
        key, value = bind_params(params, ("key", "value"), 2)
        check_name("key", key)
        self.memory.put(key, encode_value(value), active.run_id)
        return None

    async def memory_get(self, active, params):
        (key,) = bind_params(params, ("key",), 1)
        check_name("key", key)
        return self.memory.get(key)


class SharedMemory:
    """The robot's shared memory: key -> value, held as JSON texts, with its limits per robot
    and per run (the run that last set a key answers for it). Reads and writes as a dict of
    values too (``memory[key]``), as tests do."""

    def __init__(self, running=lambda run: True):
        self.entries: dict[str, tuple[str, int, int]] = {}  # key -> (JSON text, run, bytes)
        self.bytes = 0
        self.by_run: dict[int, list[int]] = {}  # run -> [keys, bytes] it last set
        self.running = running  # running(run): whether that run is still on

    def put(self, key: str, text: str, run: int) -> None:
        old = self.entries.get(key)
        cost = len(key) + len(text) + OVERHEAD
        old_cost = old[2] if old is not None else 0
        mine = self.by_run.get(run, [0, 0])
        same_run = old is not None and old[1] == run
        if mine[0] + (0 if same_run else 1) > MAX_MEMORY_KEYS_RUN:
            raise LimitReached(_memory_full(f"a run sets at most {MAX_MEMORY_KEYS_RUN} keys"))
        if mine[1] + cost - (old_cost if same_run else 0) > MAX_MEMORY_BYTES_RUN:
            raise LimitReached(_memory_full(f"a run sets at most {MAX_MEMORY_BYTES_RUN // MB} MB"))
        self.make_room(key, cost - old_cost, new_key=old is None)
        if old is None and len(self.entries) >= MAX_MEMORY_KEYS:
            raise LimitReached(_memory_full(f"at most {MAX_MEMORY_KEYS} keys"))
        if self.bytes - old_cost + cost > MAX_MEMORY_BYTES:
            raise LimitReached(_memory_full(f"{MAX_MEMORY_BYTES // MB} MB in all"))
        if old is not None:
            self._account(old[1], -1, -old_cost)
        self.entries[key] = (text, run, cost)
        self._account(run, 1, cost)

    def make_room(self, key: str, more: int, new_key: bool) -> None:
        """Keys stay after their program ends, until the room is needed: then the oldest set
        by ended runs go, as shown values do (else ended runs would fill it for good)."""
        for other, (_, run, cost) in list(self.entries.items()):
            full = (new_key and len(self.entries) >= MAX_MEMORY_KEYS) or (
                self.bytes + more > MAX_MEMORY_BYTES
            )
            if not full:
                return
            if other != key and not self.running(run):
                del self.entries[other]
                self._account(run, -1, -cost)

    def _account(self, run: int, keys: int, cost: int) -> None:
        self.bytes += cost
        mine = self.by_run.setdefault(run, [0, 0])
        mine[0] += keys
        mine[1] += cost
        if not mine[0]:
            del self.by_run[run]

    def get(self, key, default=None):
        kept = self.entries.get(key)
        return default if kept is None else json.loads(kept[0])

    def __getitem__(self, key):
        return json.loads(self.entries[key][0])

    def __setitem__(self, key, value) -> None:
        self.put(key, encode_value(value), 0)

    def __contains__(self, key) -> bool:
        return key in self.entries

    def __len__(self) -> int:
        return len(self.entries)


def _memory_full(why: str) -> str:
    return f"the shared memory is full ({why}): set keys you have already instead"


def encode_value(value) -> str:
    """A published or kept value as the JSON text it is held as; ValueError if too large."""
    text = _encode(value)
    if len(text) > MAX_MESSAGE_BYTES:
        raise ValueError(f"value larger than {MAX_MESSAGE_BYTES // 1024} KB")
    return text


def check_name(what: str, name) -> None:
    if not isinstance(name, str) or not 0 < len(name) <= MAX_SHOW_NAME:
        raise ValueError(f"{what} must be a text of 1 to {MAX_SHOW_NAME} characters")


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
