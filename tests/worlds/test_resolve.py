"""A sim's world setting resolved for its driver (worlds.resolve, called by the robot's agent):
a stored world's id or name -> its document, a built-in name as it is; a world the robot's
owner may not see, or none, refused with the reason; saving, sharing or deleting a world
tells the sims in it to reopen (robot.reconfigure)."""

import asyncio

import pytest
from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer

from robots.models import Robot, agent_channel
from tests.worlds.documents import corridor
from worlds.documents import validated
from worlds.models import World
from worlds.resolve import WorldUnavailable, driver_options, robots_using, world_option
from worlds.shares import add_share

pytestmark = pytest.mark.django_db


def stored(owner, name="corridor") -> World:
    document = validated(corridor(name=name), name)
    world = World.objects.create(owner=owner, name=name, title=document["title"])
    world.save_document(document, owner)
    return world


def sim(name, url="sim://", owner=None, **settings) -> Robot:
    return Robot.objects.create(name=name, url=url, owner=owner, settings=settings)


def test_id_or_name_becomes_the_document(people):
    alice = people["alice"]
    world = stored(alice)
    by_id = sim("a1", f"sim://?world={world.pk}&max_linear=0.3", alice)
    assert world_option(by_id) == {"world": world.document}  # the URL's others: rhal.connect's
    by_name = sim("a2", "sim://", alice, world="corridor", max_linear=0.3)
    assert world_option(by_name) == {"world": world.document, "max_linear": 0.3}
    in_settings = sim("a3", "sim://?world=maze", alice, world=str(world.pk))
    assert world_option(in_settings)["world"] == world.document  # the settings win, as in connect


def test_builtin_names_pass_through(people):
    stored(people["alice"], "maze-copy")
    assert world_option(sim("b1", "sim://?world=maze", people["alice"])) == {"world": "maze"}
    assert world_option(sim("b2", "sim://?world=builtin:line"))["world"] == "line"
    assert world_option(sim("b3", "sim://?arena=square")) == {}  # the old option, untouched
    assert world_option(sim("b4", "pioneer:///dev/null", world=3)) == {"world": 3}  # not a sim's


def test_unknown_or_unseen_world_is_refused(people):
    world = stored(people["alice"])
    robots = [
        sim("c1", f"sim://?world={world.pk}", people["bob"]),
        sim("c2", "sim://?world=corridor", people["bob"]),
        sim("c3", f"sim://?world={world.pk}"),  # no owner: worlds shared with everyone only
        sim("c4", "sim://?world=nowhere", people["alice"]),
        sim("c5", "sim://?world=builtin:nowhere", people["alice"]),
    ]
    for robot in robots:
        with pytest.raises(WorldUnavailable, match="no world"):
            world_option(robot)
        options, why = driver_options(robot)
        assert options["world"] == "boxes" and "no world" in str(why)  # built, never opened
    add_share(world, people["alice"], group="class-a")
    assert world_option(robots[0])["world"] == world.document
    assert world_option(robots[1])["world"] == world.document
    with pytest.raises(WorldUnavailable):
        world_option(robots[2])
    add_share(world, people["alice"], everyone=True)
    assert driver_options(robots[2]) == ({"world": world.document}, None)


def test_a_name_is_the_owners_own_first(people):
    mine = stored(people["bob"])
    theirs = stored(people["alice"])
    add_share(theirs, people["alice"], everyone=True)
    assert world_option(sim("d1", "sim://?world=corridor", people["bob"]))["world"] == (
        mine.document
    )
    # Two of that name shared with carol, none hers: which one is for her to say (its id).
    add_share(mine, people["bob"], everyone=True)
    with pytest.raises(WorldUnavailable, match="several"):
        world_option(sim("d2", "sim://?world=corridor", people["carol"]))


def test_saving_tells_the_sims_in_it(people, api, django_capture_on_commit_callbacks):
    alice = people["alice"]
    world = stored(alice)
    sim("e1", f"sim://?world={world.pk}", alice)
    sim("e2", "sim://", alice, world="corridor")
    sim("e3", "sim://?world=corridor", people["carol"])  # it names one it may not see
    sim("e4", "sim://?world=maze", alice)
    sim("e5", "sim://", alice)
    assert sorted(robots_using(world)) == ["e1", "e2", "e3"]

    layer = get_channel_layer()
    async_to_sync(layer.flush)()
    with django_capture_on_commit_callbacks(execute=True):  # told once it is committed
        saved = api["alice"]("PUT", f"/api/worlds/{world.pk}", corridor(title="Moved"))
    assert saved.status_code == 200
    for name in ("e1", "e2", "e3"):
        message = async_to_sync(receive)(agent_channel(name))
        assert message["type"] == "robot.reconfigure"
    assert async_to_sync(nothing_for)(agent_channel("e4"))


async def receive(channel: str) -> dict:
    return await asyncio.wait_for(get_channel_layer().receive(channel), 10)


async def nothing_for(channel: str) -> bool:
    layer = get_channel_layer()
    return not layer.channels.get(channel) if hasattr(layer, "channels") else True


def test_staff_set_a_stored_world_on_a_robot(people):
    """A robot's URL or settings naming a stored world pass the edit's check (its driver built
    with the document); a world no one has is refused there, saying so."""
    from tests.worlds.conftest import api_of

    staff = people["tina"]
    staff.is_staff = True
    staff.save()
    world = stored(people["alice"])
    sim("lab-sim", "sim://")
    call = api_of(staff)
    by_url = call("PATCH", "/api/robots/lab-sim", {"url": f"sim://?world={world.pk}"})
    assert by_url.status_code == 200, by_url.content
    by_name = call("PATCH", "/api/robots/lab-sim", {"settings": {"world": "corridor"}})
    assert by_name.status_code == 200, by_name.content
    refused = call("PATCH", "/api/robots/lab-sim", {"settings": {"world": "nowhere"}})
    assert refused.status_code == 422 and "no world 'nowhere'" in refused.json()["detail"]
    # Set, but its owner (none: the lab's) may not use alice's private world: said at its open.
    robot = Robot.objects.get(name="lab-sim")
    assert "no world" in str(driver_options(robot)[1])
