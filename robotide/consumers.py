"""What every robotide consumer shares."""

from channels.consumer import get_handler_name


class DirectDispatch:
    """Handles each message at once, without channels' trip to the database thread first.

    channels (4.x) closes stale database connections before every message a consumer handles,
    in a trip to the one thread that runs all database work (thread-sensitive sync_to_async).
    A run's first output line then waited there behind its start's database writes (its claim,
    its state), 10 ms and more on a busy machine, and every line and telemetry message after it
    behind whatever else was queued. Every database access of ours goes through
    database_sync_to_async, which closes stale connections itself, before and after.
    """

    async def dispatch(self, message):
        handler = getattr(self, get_handler_name(message), None)
        if handler is None:
            raise ValueError(f"No handler for message type {message['type']}")
        await handler(message)
