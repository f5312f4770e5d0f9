"""A robot agent's resets: a simulated robot put back at its world's start pose (or a pose
given), stopped, with a fresh odometer, battery and path; and where each run starts.

``robot.reset {pose?, by, override?, reply_to}`` (robots.reset asks it; staff and the robot's
owner send ``override``) answers ``{"ok": true}``, or ``{"ok": false, "refused": code,
"detail": why}`` as robot.hear does (robots.reset says it in the reader's language):

- ``not_sim``: the driver cannot be reset (a real robot: only simulated robots can);
- ``busy``: a run of someone else's is going on the robot (``run``, ``user``): a reset under
  it would move its robot from under its program. Staff and the owner may all the same; one's
  own run goes on from where the reset put the robot;
- ``pose``: the driver refused the pose (outside the arena, overlapping something), in its
  plain words.

A reset stops hand driving (whoever drives by hand keeps the lease: their next press drives
on) and may be done during an emergency stop (it places the robot; it moves nothing).

Where a run starts (``before_run``, awaited just before its program may run, when no other
run is going on the robot): at the pose of the last reset that gave one, if any (once: that
run only, whatever ``start_each_run`` says: how a teacher or a test sets up a situation); else
at the world's start pose if the robot's ``start_each_run`` setting is true; else where the
robot is. A reset without a pose forgets a pose given before, and so does the robot being
reopened with other settings (another world). Kept in the agent's memory only.
"""

import asyncio
import logging

import rhal

log = logging.getLogger(__name__)

NOT_SIM = "only simulated robots can be reset"


class StartPose:
    """One per agent (RobotAgent.starts): the robot.reset handler and each run's start."""

    def __init__(self, agent):
        self.agent = agent
        # (driver, pose): the pose the next run starts at, given to that driver.
        self.pending: tuple[object, tuple[float, float, float]] | None = None
        self.handlers = {"robot.reset": self._asked}

    def can_reset(self) -> bool:
        return asyncio.iscoroutinefunction(getattr(self.agent.driver, "reset", None))

    async def _asked(self, message: dict) -> None:
        pose = message.get("pose")
        reply = await self.reset(
            tuple(pose) if pose is not None else None,
            message.get("by", ""),
            override=message.get("override", False),
        )
        await self.agent.reply(message, reply)

    async def reset(self, pose=None, by: str = "", override: bool = False) -> dict:
        if not self.can_reset():
            return _refused("not_sim", NOT_SIM)
        other = self._others_run(by)
        if other is not None and not override:
            detail = f"run #{other.run_id} of {other.user or 'someone'} is going on the robot"
            return _refused("busy", detail, run=other.run_id, user=other.user)
        try:
            await self._place(pose)
        except ValueError as exc:  # the driver's own words: outside the arena, overlapping...
            return _refused("pose", str(exc))
        self.pending = (self.agent.driver, pose) if pose is not None else None
        log.info("agent %s: reset by %s to %s", self.agent.name, by or "?", pose or "the start")
        return {"ok": True}

    def _others_run(self, by: str):
        """A run going on the robot that is not ``by``'s, if any."""
        return next((a for a in self.agent.runs.values() if not by or a.user != by), None)

    async def _place(self, pose) -> None:
        agent = self.agent
        if agent._deadman is not None:  # hand driving stops: nothing to stop after
            agent._deadman.cancel()
        agent.motion_owner = None
        if pose is None:
            await agent.driver.reset()
        else:
            await agent.driver.reset(pose)
        if (poses := getattr(agent, "poses", None)) is not None:
            poses.wake()  # pages that draw it see it where it is now

    async def before_run(self, run_id: int) -> None:
        """The run's robot where the run starts (see the module's doc); a failure is logged
        and the run starts where the robot is."""
        agent = self.agent
        if not self.can_reset() or any(other != run_id for other in agent.runs):
            return
        given, self.pending = self.pending, None
        pose = given[1] if given is not None and given[0] is agent.driver else None
        if pose is None and not agent.start_each_run:
            return
        try:
            await self._place(pose)
        except (ValueError, rhal.RhalError) as exc:
            log.warning("agent %s: run %s starts where the robot is: %s", agent.name, run_id, exc)


def _refused(code: str, detail: str, **more) -> dict:
    return {"ok": False, "refused": code, "detail": detail, **more}
