"""/healthz: is this web worker able to serve? For load balancers and compose health checks."""

import asyncio

from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.db import connection
from django.http import JsonResponse

CHECK_TIMEOUT = 2.0


def healthz(request):
    """200 when the database and the channel layer answer; 503 naming what does not."""
    checks = {"database": _database(), "channels": _channels()}
    healthy = all(value == "ok" for value in checks.values())
    return JsonResponse(checks, status=200 if healthy else 503)


def _database() -> str:
    try:
        with connection.cursor() as cursor:
            cursor.execute("SELECT 1")
    except Exception as exc:  # any failure is the answer
        return f"failed: {type(exc).__name__}"
    return "ok"


def _channels() -> str:
    async def round_trip():
        layer = get_channel_layer()
        channel = await layer.new_channel("healthz.")
        await layer.send(channel, {"type": "healthz"})
        await asyncio.wait_for(layer.receive(channel), CHECK_TIMEOUT)

    try:
        async_to_sync(round_trip)()
    except Exception as exc:  # Redis away, or too slow
        return f"failed: {type(exc).__name__}"
    return "ok"
