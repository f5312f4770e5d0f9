"""Fixtures of the classroom's tests."""

import pytest
from channels.layers import get_channel_layer


@pytest.fixture
async def agents():
    """Embedded mode's agents: one per robot, the check sims' started as they are made."""
    from robots.agent import AgentManager

    await get_channel_layer().flush()
    manager = AgentManager()
    await manager.start()
    yield manager
    await manager.shutdown()
