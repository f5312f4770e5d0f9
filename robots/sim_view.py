"""What a browser needs to draw a simulated robot itself: its pose stream and its world.

Agent side of the sim view (static/robotide/simview.js draws it). Instead of a JPEG rendered
per frame, a sim's agent publishes ``robot.pose`` to the robot's group at up to POSE_RATE Hz
while the robot moves, and once when it stops or is put somewhere else (a reset): a page draws
at its display's rate, extrapolating along the arc of the last pose's speeds. A still robot
costs nothing: the loop sleeps until a drive command wakes it, or the telemetry loop (which
reads the sensors anyway) sees the pose differ from the last one sent.

Only while someone watches: a page's socket sends ``pose.watch {viewer}`` at once and every
WATCH_RENEW s (``pose.unwatch`` when it closes); a viewer not heard of for WATCH_LEASE s is
forgotten. A moving sim nobody watches publishes nothing (30 unwatched moving sims cost a
quarter of a core before).

``robot.world {reply_to}`` answers ``{world, robot, speed}``: the world document the sim runs
in, its robot's shape and sensors, and its time scale (GET /robots/<name>/world.json).
"""

import asyncio

import rhal

POSE_RATE = 20.0  # Hz, at most, while the robot moves
WATCH_RENEW = 3.0  # s between a page's pose.watch messages (as the camera's viewers)
WATCH_LEASE = 10.0  # a viewer silent this long is forgotten (a crashed web process lets go)
DIGITS = 4  # 0.1 mm, 0.1 mrad: plenty for a picture, short on the wire


def is_sim(driver) -> bool:
    return getattr(driver, "kind", "") == "sim"


def sim_info(driver) -> dict | None:
    """For the robot.state reply: the sim's world name and time scale; None for a real robot."""
    if not is_sim(driver):
        return None
    sim = driver.capabilities().get("sim") or {}
    return {"world": sim.get("world", ""), "speed": sim.get("speed", 1)}


def pose_of(readings: dict) -> tuple | None:
    """What a page draws from a reading: x, y, theta, linear, angular, bumper, range, sonar;
    None for a reading without a position (an error)."""
    position, velocity = readings.get("position"), readings.get("velocity") or {}
    if not isinstance(position, dict):
        return None
    sonar = readings.get("sonar")
    return (
        round(position["x"], DIGITS),
        round(position["y"], DIGITS),
        round(position["theta"], DIGITS),
        round(velocity.get("linear", 0.0), DIGITS),
        round(velocity.get("angular", 0.0), DIGITS),
        bool(readings.get("bumper")),
        _metres(readings.get("range")),
        tuple(_metres(r) for r in sonar) if isinstance(sonar, list) else None,
    )


def _metres(value) -> float | None:
    return round(value, DIGITS) if isinstance(value, (int, float)) else None


def pose_fields(pose: tuple) -> dict:
    """A read pose (pose_of's and the sim's clock) as robot.pose names its fields."""
    x, y, theta, linear, angular, bumper, range_m, sonar, t = pose
    fields = {
        "x": x, "y": y, "theta": theta, "linear": linear, "angular": angular,
        "bumper": bumper, "range": range_m,
        "t": round(t, DIGITS) if isinstance(t, (int, float)) else None,
    }  # fmt: skip
    if sonar is not None:
        fields["sonar"] = list(sonar)
    return fields


def moving(pose: tuple) -> bool:
    return pose[3] != 0.0 or pose[4] != 0.0


class PoseStream:
    """One per agent; serves while the agent does, publishing only for a sim driver."""

    def __init__(self, agent):
        self.agent = agent
        self.last: tuple | None = None  # the last pose sent
        self._wake = asyncio.Event()
        self.viewers: dict[str, float] = {}  # viewer -> when its lease ends (loop time)
        self.handlers = {
            "robot.world": self.world,
            "pose.watch": self.watch,
            "pose.unwatch": self.unwatch,
        }

    async def watch(self, message: dict) -> None:
        first = not self.watched
        self.viewers[message["viewer"]] = asyncio.get_running_loop().time() + WATCH_LEASE
        if first:  # where it is now, and on from there if it moves
            self.last = None
            self._wake.set()

    async def unwatch(self, message: dict) -> None:
        self.viewers.pop(message["viewer"], None)

    @property
    def watched(self) -> bool:
        now = asyncio.get_running_loop().time()
        for viewer in [v for v, ends in self.viewers.items() if ends < now]:
            del self.viewers[viewer]
        return bool(self.viewers)

    def wake(self) -> None:
        """A drive command, a stop or a reset went to the robot: look at its pose now."""
        self._wake.set()

    def noticed(self, readings: dict) -> None:
        """The telemetry loop's reading: wakes the stream if the robot is not where it was
        last sent (put elsewhere by something that did not wake it, e.g. a reset)."""
        if is_sim(self.agent.driver) and not self._wake.is_set():
            pose = pose_of(readings)
            if pose is not None and (self.last is None or pose[:3] != self.last[:3]):
                self._wake.set()

    async def serve(self) -> None:
        interval = 1.0 / POSE_RATE
        while True:
            await self._wake.wait()
            self._wake.clear()
            if not is_sim(self.agent.driver) or not self.watched:
                continue
            before = None  # the last read of this wake's
            while True:
                pose = await self._read()
                if pose is None:
                    break
                if before is not None and pose[:3] == before[:3]:
                    # Commanded but not moving (pressing on a wall): a page that extrapolated
                    # the command would draw the robot going into it.
                    pose = pose[:3] + (0.0, 0.0) + pose[5:]
                before = pose
                if pose[:-1] != self.last:
                    self._publish(pose)
                if not moving(pose) or not self.watched:
                    break
                await asyncio.sleep(interval)

    async def _read(self) -> tuple | None:
        """The pose now and the sim's clock; None while the robot cannot be read."""
        try:
            readings = await self.agent.driver.sensors()
        except rhal.RhalError:
            return None
        pose = pose_of(readings)
        return None if pose is None else pose + (readings.get("time"),)

    def _publish(self, pose: tuple) -> None:
        self.last = pose[:-1]
        message = {"type": "robot.pose", "robot": self.agent.name, **pose_fields(pose)}
        self.agent.publish(self.agent.group, message)

    async def world(self, message: dict) -> None:
        driver = self.agent.driver
        if not is_sim(driver):
            await self.agent.reply(message, {"error": f"robot {self.agent.name} is no sim"})
            return
        answer = {"world": driver.world_doc(), "robot": driver.robot_doc()}
        answer["speed"] = sim_info(driver)["speed"]
        # Where it is now: a page draws it at once, still or not, then follows robot.pose.
        pose = await self._read()
        if pose is not None:
            answer["pose"] = pose_fields(pose)
        await self.agent.reply(message, answer)
