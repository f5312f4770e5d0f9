"""Personal sims: a simulated robot of one's own, so a class of 25 does not queue for 7 robots.

A personal sim is a normal robot (``sim://``, its own agent, its runs boxed and logged like any
other) with ``personal`` set and its user as ``owner``. Only its owner, staff and the teachers
of its owner's classes see, drive and stop it (robots.models.robots_for_user, Robot._allows);
only its owner's programs run on it, so nobody queues for it. Each run starts at its world's
start pose (``start_each_run``).

- Made by ``POST /api/sims`` (robots.sims_api) or the workbench's "My sim" (``MY_SIM``), up to
  SIMS_PER_USER a user and SIMS_MAX on the server; named ``sim-<username>-<n>``.
- A *twin* of a robot copies what a program can tell of it: its top speeds, its sonar ring
  (as angles), a floor (light) sensor, a range cone as wide as the discs that make its
  ``range``, and its camera, so a program that works on the twin runs unchanged on the robot.
  Read off the robot's driver built from its URL and options (nothing is opened), and, when
  its agent answers at once, the speeds and model the live robot reports.
- *Reaped* when unused for SIM_IDLE_MINUTES (no run going, none asked, not made, chosen or
  reset since): its agent stops and the row is deleted, or, while runs name it, kept with
  ``reaped`` set, out of every list and agent, so that its runs and their logs stay readable
  by their owners. Its owner may delete it sooner (``DELETE /api/sims/{name}``).

Where the reaper runs: in embedded mode, in the web process, beside the agents
(robots.agent.AgentManager.start); in fleet mode, in ``robotide agent --personal-sims``, the
process that also runs the personal sims' agents (one such process per fleet: a second stands
by until the first ends, robots.agent_lock).
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import math
from datetime import timedelta

from django.conf import settings
from django.contrib.auth import get_user_model
from django.core.exceptions import PermissionDenied
from django.db import IntegrityError, models, transaction
from django.db.models import Max, ProtectedError, Q
from django.http import Http404
from django.utils import timezone
from django.utils.text import slugify
from django.utils.translation import gettext as _
from django.utils.translation import ngettext

import rhal
from programs.models import Run
from rhal.registry import driver_class
from robots.bus import announce_robot_sync, ask_agent_sync, blocking
from robots.models import Robot, get_robot_for_user, manager_channel
from robots.runs import RunRefused
from worlds.resolve import WorldUnavailable, find_world

log = logging.getLogger(__name__)

#: The workbench's choice "My sim": the user's sim, made when they first run on it.
MY_SIM = "+sim"
REAP_EVERY = 60.0  # seconds between the reaper's looks
TOUCH_EVERY = timedelta(minutes=1)  # `used` is written at most this often (not per page view)
TWIN_ASK_TIMEOUT = 1.0  # s the twin waits for the real robot's agent before reading its driver
# The width of one Pioneer sonar disc's beam (a Polaroid 6500 ranging module: about 30°): a
# twin's range cone spans the discs that make the robot's `range`, and half a beam either side.
SONAR_BEAM_DEG = 30.0
DESCRIPTION = "Simulated robot"  # robots.models.DESCRIPTIONS: shown translated


class SimRefused(RunRefused):
    """No sim made (a cap reached, a world unknown): its message says why and what to do."""


class UnknownWorld(ValueError):
    pass


# -- whose, and how many -------------------------------------------------------------------


def sims_of(user):
    """``user``'s own personal sims, not removed (nor their check sims: robots.check_sims)."""
    if not user.is_authenticated:
        return Robot.objects.none()
    return Robot.objects.filter(personal=True, checking=False, owner=user, reaped__isnull=True)


def offered(user) -> bool:
    """Whether ``user`` may make a sim of their own (personal sims are not switched off)."""
    return user.is_authenticated and settings.SIMS_PER_USER > 0


def get_sim_for_user(user, name: str) -> Robot:
    """A personal sim ``user`` may see (404 else, as for any robot)."""
    robot = get_robot_for_user(user, name)
    if not robot.personal:
        raise Http404(_("%(name)s is not a personal sim.") % {"name": repr(name)})
    return robot


def _check_caps(user) -> None:
    mine = sims_of(user).count()
    if mine >= settings.SIMS_PER_USER:
        raise SimRefused(
            ngettext(
                "you have %(count)s sim already (your limit is %(limit)s): delete it, or reuse it",
                "you have %(count)s sims already (your limit is %(limit)s): delete one, or reuse"
                " it",
                mine,
            )
            % {"count": mine, "limit": settings.SIMS_PER_USER}
        )
    everyone = Robot.objects.filter(personal=True, checking=False, reaped__isnull=True).count()
    if everyone >= settings.SIMS_MAX:
        raise SimRefused(
            _(
                "the server has %(count)s sims already (its limit is %(limit)s): try again"
                " later, when an idle one has been removed, or ask your teacher"
            )
            % {"count": everyone, "limit": settings.SIMS_MAX}
        )


def name_base(user) -> str:
    """``sim-<username>``, the username as a slug (a robot's name is one)."""
    slug = slugify(user.get_username())[:40].strip("-_") or f"user{user.pk}"
    return f"sim-{slug}"


def free_name(user) -> str:
    base = name_base(user)
    taken = set(Robot.objects.filter(name__startswith=f"{base}-").values_list("name", flat=True))
    number = 1
    while f"{base}-{number}" in taken:
        number += 1
    return f"{base}-{number}"


# -- making one ------------------------------------------------------------------------------


def create(user, twin_of: str | None = None, world=None) -> Robot:
    """A new personal sim of ``user``'s, its agent started. Http404 for a twin of a robot
    they may not see; UnknownWorld; SimRefused past a cap."""
    if not offered(user):
        raise SimRefused(_("Personal sims are switched off on this server."))
    options: dict = {"start_each_run": True}
    real = None
    if twin_of:
        real = get_robot_for_user(user, twin_of)  # one they may not see: 404
        options.update(twin_options(real))
    url = "sim://" if world in (None, "") else f"sim://?world={world_value(user, world)}"
    for _attempt in range(3):  # two makers at once may pick the same free name
        try:
            with transaction.atomic():
                # One maker at a time per user: two tabs cannot both pass the cap.
                get_user_model().objects.select_for_update().filter(pk=user.pk).first()
                _check_caps(user)
                robot = Robot.objects.create(
                    name=free_name(user), url=url, settings=options, description=DESCRIPTION,
                    owner=user, personal=True, twin_of=real.name if real else "",
                    used=timezone.now(),
                )  # fmt: skip
            break
        except IntegrityError:
            continue
    else:
        raise SimRefused(_("Could not find a free name for a new sim: try again."))
    announce(robot.name)
    log.info("personal sim %s made for %s (%s)", robot.name, user.get_username(), url)
    return robot


def my_sim(user) -> Robot:
    """The workbench's "My sim": the user's sim (the one used last), made if they have none."""
    robot = sims_of(user).order_by("-used", "-pk").first()
    if robot is None:
        return create(user)
    touch(robot)
    return robot


def announce(name: str) -> None:
    """Its agent starts (embedded mode: the web process's AgentManager; fleet mode: ``robotide
    agent --personal-sims``). Not sure to be heard: the robot is made all the same."""
    try:
        announce_robot_sync(name)
    except Exception:  # the channel layer away: its agent starts with the next manager start
        log.exception("personal sim %s: could not announce it to the agents", name)


def world_value(user, world) -> str:
    """What the sim's URL names as its world: a built-in's name, or a stored world's id (it
    stays the same world when renamed); UnknownWorld if ``user`` may use none such."""
    try:
        found = find_world(world, user)
    except WorldUnavailable as exc:
        raise UnknownWorld(str(exc)) from None
    return found if isinstance(found, str) else str(found.pk)


# -- a twin ----------------------------------------------------------------------------------


def twin_options(real: Robot) -> dict:
    """The sim's driver options that make it behave as ``real`` does for a program: its top
    speeds, sonar ring, floor sensor, range cone and camera (rhal.sim takes them)."""
    if real.url.lower().startswith("sim:"):  # a twin of a sim: its robot as it is set up
        keep = ("max_linear", "max_angular", "sonar", "floor_sensor", "range_cone_deg", "camera")
        return {key: real.settings[key] for key in keep if key in real.settings}
    live = _live_state(real)
    capabilities = driver_capabilities(real, (live.get("model") or {}).get("name"))
    drive = live.get("drive") or capabilities.get("drive") or {}
    options = {key: drive[key] for key in ("max_linear", "max_angular") if _number(drive.get(key))}
    sensors = capabilities.get("sensors") or {}
    if angles := sonar_angles(sensors):
        options["sonar"] = angles
        if cone := range_cone(sensors):
            options["range_cone_deg"] = cone
    if "light" in sensors:  # an NXT's light sensor: a beginner's line follower
        options["floor_sensor"] = True
    camera = live["camera"] if "camera" in live else capabilities.get("camera") is not None
    configured = real.settings.get("camera")
    camera = camera or bool(isinstance(configured, dict) and configured.get("device"))
    if _sim_takes("camera"):
        options["camera"] = camera
    return options


def _live_state(real: Robot) -> dict:
    """The real robot's agent's robot.state (its speeds, its model as it named it), if it
    answers at once; {} else."""
    if not real.online:
        return {}
    try:
        return ask_agent_sync(real.name, "robot.state", timeout=TWIN_ASK_TIMEOUT)
    except Exception:  # away (AgentUnavailable), or a bus error: the driver's word instead
        return {}


def driver_capabilities(real: Robot, model: str | None = None) -> dict:
    """What ``real``'s driver says it can do, built from its URL and options (opened never);
    ``model``: the one the live robot named (a Pioneer's sonar ring is its model's)."""
    options = real.driver_options()
    if model and _takes(real.url, "model") and not options.get("model"):
        options["model"] = model
    try:
        return rhal.connect(real.url, **options).capabilities()
    except (TypeError, ValueError, rhal.RhalError) as exc:
        log.warning("twin of %s: its driver says nothing (%s)", real.name, exc)
        return {}


def sonar_angles(sensors: dict) -> list[float]:
    """A sonar ring's discs as angles (degrees CCW from ahead), in the robot's sonar order."""
    discs = (sensors.get("sonar") or {}).get("discs") or []
    return [float(disc["heading"]) for disc in discs if _number(disc.get("heading"))]


def range_cone(sensors: dict) -> float | None:
    """The cone a robot's ``range`` sees when it is its front sonars' nearest echo."""
    discs = (sensors.get("sonar") or {}).get("discs") or []
    front = (sensors.get("range") or {}).get("sonars") or []
    headings = [abs(discs[i]["heading"]) for i in front if 0 <= i < len(discs)]
    if not headings:
        return None
    return round(2 * max(headings) + SONAR_BEAM_DEG, 1)


def _number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _takes(url: str, option: str) -> bool:
    try:
        return option in inspect.signature(driver_class(url).__init__).parameters
    except rhal.RhalError:  # no such driver here
        return False


def _sim_takes(option: str) -> bool:
    return _takes("sim://", option)


# -- in use, and removed when not --------------------------------------------------------------


def touch(robot: Robot) -> None:
    """A personal sim was chosen, watched or reset: not idle (written once a minute at most)."""
    if not robot.personal:
        return
    now = timezone.now()
    Robot.objects.filter(pk=robot.pk).filter(
        Q(used__isnull=True) | Q(used__lt=now - TOUCH_EVERY)
    ).update(used=now)


class SimBusy(RunRefused):
    pass


def delete(user, robot: Robot) -> None:
    """Its owner (or staff) removes a sim now; SimBusy while a run of it goes or waits."""
    if not (robot.owner_id == user.pk or user.is_staff):
        raise PermissionDenied(_("Only its owner and staff delete a personal sim."))
    if Run.objects.filter(robot=robot, state__in=Run.ONGOING).exists():
        raise SimBusy(
            _("%(name)s has a run going or waiting: stop it first.") % {"name": robot.name}
        )
    if remove(robot):
        tell_removed(robot.name)


def remove(robot: Robot) -> bool:
    """Out of every list and agent: deleted, or kept (``reaped``) while runs name it."""
    now = timezone.now()
    if not Robot.objects.filter(pk=robot.pk, reaped__isnull=True).update(reaped=now):
        return False  # removed already
    try:
        with transaction.atomic():
            Robot.objects.filter(pk=robot.pk, runs__isnull=True).delete()
    except ProtectedError:  # a run came meanwhile: the row stays, reaped
        pass
    log.info("personal sim %s removed", robot.name)
    return True


def idle_sims(now=None) -> list[Robot]:
    """The personal sims unused for SIM_IDLE_MINUTES: nothing going or waiting on them, and
    no run asked or ended, nor the sim made, chosen or reset since."""
    now = now or timezone.now()
    cutoff = now - timedelta(minutes=settings.SIM_IDLE_MINUTES)
    candidates = Robot.objects.filter(personal=True, reaped__isnull=True).filter(
        Q(used__lt=cutoff) | Q(used__isnull=True, created__lt=cutoff)
    )
    idle = [robot for robot in check_sims_done() if robot not in candidates]
    for robot in candidates:
        runs = Run.objects.filter(robot=robot)
        if runs.filter(state__in=Run.ONGOING).exists():
            continue
        last = runs.aggregate(asked=Max("created"), ended=Max("ended"))
        if any(when is not None and when >= cutoff for when in last.values()):
            continue
        idle.append(robot)
    return idle


def check_sims_done() -> list[Robot]:
    """Check sims whose run ended without their agent removing them (the run failed before
    an agent took it, or its agent went away): removed at the reaper's next look."""
    done = Robot.objects.filter(checking=True, reaped__isnull=True, runs__isnull=False)
    going = Run.objects.filter(robot=models.OuterRef("pk"), state__in=Run.ONGOING)
    return list(done.exclude(models.Exists(going)).distinct())


def reap_idle(now=None) -> list[str]:
    """Remove the idle sims: their names (their agents are to stop)."""
    return [robot.name for robot in idle_sims(now) if remove(robot)]


def tell_removed(name: str) -> None:
    """The agents' manager stops a removed sim's agent."""
    try:
        blocking(_tell_removed)(name)
    except Exception:  # the channel layer away: the agent stops with the next manager start
        log.exception("personal sim %s: could not tell the agents it was removed", name)


async def tell_removed_async(name: str) -> None:
    """``tell_removed`` from the loop (a check sim's agent, robots.check_sims)."""
    await _tell_removed(name)


async def _tell_removed(name: str) -> None:
    from channels.layers import get_channel_layer

    await get_channel_layer().send(manager_channel(), {"type": "robot.removed", "name": name})


async def reap_loop(stop_agent) -> None:
    """Until cancelled: every REAP_EVERY s, remove the idle sims and stop their agents
    (``stop_agent(name)``, a coroutine function of the AgentManager)."""
    from channels.db import database_sync_to_async

    while True:
        await asyncio.sleep(REAP_EVERY)
        try:
            for name in await database_sync_to_async(reap_idle)():
                log.info("personal sim %s unused for %g min: removed", name, idle_minutes())
                await stop_agent(name)
        except Exception:  # the database away for a moment: look again next time
            log.exception("personal sims: the reaper failed")


def idle_minutes() -> float:
    return settings.SIM_IDLE_MINUTES


def robots_to_serve(personal_only: bool = False) -> list[str]:
    """The robots an AgentManager starts agents for: all but removed sims (embedded mode), or
    the personal sims only (``robotide agent --personal-sims``)."""
    robots = Robot.objects.filter(reaped__isnull=True)
    if personal_only:
        robots = robots.filter(personal=True)
    return list(robots.values_list("name", flat=True))


def serves(name: str, personal_only: bool) -> bool:
    """Whether a manager serving ``personal_only`` starts an agent for robot ``name``."""
    robots = Robot.objects.filter(name=name, reaped__isnull=True)
    return robots.filter(personal=True).exists() if personal_only else robots.exists()
