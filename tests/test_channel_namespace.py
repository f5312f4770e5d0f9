"""Two robotides on one Redis server, given other databases of it, do not take each other's
messages: Redis's publish/subscribe channels (the fleet's channel layer) ignore the database,
so its number goes into every channel's and group's name (robotide.settings.channel_namespace)."""

import asyncio
import contextlib

import pytest
from channels_redis.pubsub import RedisPubSubChannelLayer

from robotide.settings import channel_namespace, redis_layer_config
from robots.models import agent_channel
from tests.appliance import REDIS, claim_redis_db, release_redis_db


@pytest.mark.parametrize(
    ("url", "namespace"),
    [
        ("", ""),
        ("redis://127.0.0.1:6379", ""),
        ("redis://127.0.0.1:6379/0", ""),
        ("redis://:secret@127.0.0.1:6379/3", "db3."),
        ("rediss://cache.lab:6380/12", "db12."),
        ("unix:///run/redis/redis.sock?db=2", "db2."),
        ("unix:///run/redis/redis.sock", ""),
    ],
)
def test_the_namespace_names_the_database(url, namespace):
    assert channel_namespace(url) == namespace


def test_an_agents_channel_is_in_the_namespace(settings):
    settings.CHANNEL_NAMESPACE = "db7."
    assert agent_channel("sim") == "db7.agent.sim"


class Robotide:
    """The channel layer and the sim robot's agent's channel robotide.settings makes for this
    REDIS_URL."""

    def __init__(self, url: str):
        self.layer = RedisPubSubChannelLayer(**redis_layer_config(url))
        self.agent = f"{channel_namespace(url)}agent.sim"


async def heard(receiver: Robotide, sender: Robotide) -> bool:
    """Whether a message `sender` sends to the sim robot's agent reaches `receiver`'s."""
    listening = asyncio.ensure_future(receiver.layer.receive(receiver.agent))
    await asyncio.sleep(0.3)  # subscribed (publish/subscribe keeps nothing for latecomers)
    await sender.layer.send(sender.agent, {"type": "run.stop", "run_id": 1})
    try:
        await asyncio.wait_for(asyncio.shield(listening), 1.0)
        return True
    except TimeoutError:
        return False
    finally:
        listening.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await listening


async def test_robotides_on_other_databases_of_one_redis_are_apart():
    first, second = claim_redis_db(), claim_redis_db()
    a, b = Robotide(f"{REDIS}/{first[0]}"), Robotide(f"{REDIS}/{second[0]}")
    try:
        assert await heard(a, a)  # the layer works
        assert not await heard(b, a), "another database's robotide took the message"
    finally:
        await a.layer.flush()
        await b.layer.flush()
        release_redis_db(*first)
        release_redis_db(*second)
