"""/api/sims: one's own simulated robots (robots.sims). Each is a robot like any other for the
rest of the API (/api/robots/{name}, runs); here they are made, listed and deleted."""

from ninja import Field, Router
from ninja.errors import HttpError
from ninja.responses import Status

from programs.api import Error
from robotide.names import Name
from robotide.schemas import Body
from robots import sims
from robots.api import RobotOut

sims_router = Router(tags=["sims"])


class SimIn(Body):
    twin_of: Name | None = Field(
        None,
        max_length=50,
        description="a robot you may see: the sim gets its top speeds, sonar ring, floor sensor"
        " and camera, so that a program that works on the sim runs unchanged on it",
    )
    world: int | Name | None = Field(
        None,
        description="a built-in world (boxes, square, maze, line, rooms), or the id or name of"
        " a stored world you may see; none: the simulator's default world",
    )


@sims_router.post("", response={201: RobotOut, 404: Error, 409: Error})
def create_sim(request, data: SimIn | None = None):
    """A new simulated robot of your own, its agent started: only you, your teachers and staff
    see it, and only your programs run on it (nobody queues). Each run starts at its world's
    start pose. Answered as ``GET /api/robots/{name}`` answers. 409 past your limit of sims
    or the server's; 404 for a twin of a robot you may not see."""
    data = data or SimIn()
    try:
        robot = sims.create(request.user, data.twin_of, data.world)
    except sims.UnknownWorld as exc:
        raise HttpError(422, str(exc)) from None
    except sims.SimRefused as exc:
        return Status(409, {"detail": str(exc)})
    return Status(201, robot)


@sims_router.get("", response=list[RobotOut])
def list_sims(request):
    """Your own sims (not removed)."""
    return sims.sims_of(request.user)


@sims_router.delete("/{name}", response={204: None, 409: Error})
def delete_sim(request, name: Name):
    """Remove a sim of yours now (staff: anyone's); its runs and their logs are kept. 409 while
    a run of it goes or waits."""
    robot = sims.get_sim_for_user(request.user, name)
    try:
        sims.delete(request.user, robot)
    except sims.SimBusy as exc:
        return Status(409, {"detail": str(exc)})
    return Status(204, None)
