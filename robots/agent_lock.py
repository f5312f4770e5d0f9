"""One agent process per robot, and one `robotide agent --personal-sims` per fleet.

Two processes serving the same robot take each other's messages and starts: each marks the
other's runs lost when it starts, sweeps their cgroups, and both start the same run (one is
killed at once). So `robotide agent` takes a lock for each robot it names, and one for the
personal sims, before it serves them; a second process finds it held, says which host and pid
hold it, and stands by: it takes over when the holder ends (``--no-standby``: it exits).

The lock dies with its holder: a PostgreSQL advisory lock held by a connection of its own for
the process's life (fleet mode runs on PostgreSQL); a holder killed, its connection closes and
the lock is free. A holder whose host vanished is noticed by the server's keepalives (set on
the connection: about 25 s). A holder that loses its connection (PostgreSQL restarted, the
network cut) no longer holds anything and stops, to be started again (as compose does), so
that two never serve at once. On SQLite (one machine: the database is a file there) the lock
is an flock on a file next to it, which dies with its process in the same way.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import hashlib
import os
import socket
from pathlib import Path

from django.conf import settings
from django.db import connections

PERSONAL_SIMS = "personal sims"
STANDBY_POLL = 1.0  # s between a standby's tries: how long a takeover may lag the holder's end
WATCH_EVERY = 2.0  # s between a holder's looks at its own lock connection
# Server-side keepalives of the lock's connection (user-settable): a holder whose host is gone
# lets go after about idle + interval * count seconds.
KEEPALIVES = {"tcp_keepalives_idle": 10, "tcp_keepalives_interval": 5, "tcp_keepalives_count": 3}


class LockLost(RuntimeError):
    """The connection that held the locks is gone: another process may serve them now."""


class Refused(RuntimeError):
    """Held elsewhere, and no standby asked: said so already."""


def whoami() -> str:
    return f"pid {os.getpid()} on {socket.gethostname()}"


def lock_key(what: str) -> int:
    """A signed 64-bit key for ``what`` (a robot's name, or PERSONAL_SIMS)."""
    digest = hashlib.blake2b(f"robotide agent {what}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big", signed=True)


def agent_locks() -> PostgresLocks | FileLocks:
    if connections["default"].vendor == "postgresql":
        return PostgresLocks()
    return FileLocks(Path(settings.DATABASES["default"]["NAME"]).parent / "agent-locks")


class PostgresLocks:
    """Advisory locks on one connection of their own, taken with pg_try_advisory_lock (they
    are the database's: another robotide on another database of the server is apart)."""

    def __init__(self):
        self.conn = None

    async def _connection(self):
        if self.conn is None:
            import psycopg

            params = connections["default"].get_connection_params()
            for key in ("cursor_factory", "context"):
                params.pop(key, None)
            # Who holds a lock is read off pg_stat_activity (at most 63 characters).
            name = f"robotide agent {whoami()}"[:63]
            self.conn = await psycopg.AsyncConnection.connect(
                autocommit=True, application_name=name, **params
            )
            for setting, value in KEEPALIVES.items():
                await self.conn.execute(f"SET {setting} = {int(value)}")
        return self.conn

    async def try_take(self, what: str) -> bool:
        conn = await self._connection()
        cursor = await conn.execute("SELECT pg_try_advisory_lock(%s)", [lock_key(what)])
        return (await cursor.fetchone())[0]

    async def holder(self, what: str) -> str:
        key = lock_key(what) & 0xFFFFFFFFFFFFFFFF
        conn = await self._connection()
        cursor = await conn.execute(
            "SELECT a.application_name, a.client_addr FROM pg_locks l"
            " JOIN pg_stat_activity a ON a.pid = l.pid"
            " JOIN pg_database d ON d.oid = l.database AND d.datname = current_database()"
            " WHERE l.locktype = 'advisory' AND l.granted AND l.objsubid = 1"
            " AND l.classid::bigint = %s AND l.objid::bigint = %s",
            [key >> 32, key & 0xFFFFFFFF],
        )
        row = await cursor.fetchone()
        if row is None:
            return "another process (gone just now)"
        name, address = row
        name = name.removeprefix("robotide agent ") or "another process"
        return f"{name} (connected from {address})" if address else name

    async def watch(self) -> None:
        """Returns never; raises LockLost when the connection holding the locks is gone."""
        while True:
            await asyncio.sleep(WATCH_EVERY)
            if self.conn is None:  # nothing taken yet
                continue
            try:
                await asyncio.wait_for(self.conn.execute("SELECT 1"), WATCH_EVERY * 5)
            except Exception as exc:
                raise LockLost(f"the database connection holding its locks failed: {exc}") from exc

    async def close(self) -> None:
        if self.conn is not None:
            with contextlib.suppress(Exception):
                await self.conn.close()


class FileLocks:
    """flock on a file per lock, next to the SQLite database: its processes share a machine."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.files: dict[str, int] = {}

    def _path(self, what: str) -> Path:
        return self.folder / f"{lock_key(what) & 0xFFFFFFFFFFFFFFFF:016x}.lock"

    async def try_take(self, what: str) -> bool:
        self.folder.mkdir(mode=0o700, exist_ok=True)
        fd = os.open(self._path(what), os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return False
        os.ftruncate(fd, 0)
        os.write(fd, whoami().encode())
        self.files[what] = fd
        return True

    async def holder(self, what: str) -> str:
        try:
            return self._path(what).read_text() or "another process"
        except OSError:
            return "another process"

    async def watch(self) -> None:
        await asyncio.Event().wait()  # a file's lock is not lost while its process lives

    async def close(self) -> None:
        for fd in self.files.values():
            os.close(fd)
        self.files.clear()


async def take(locks, what: str, standby: bool, said) -> None:
    """The lock of ``what``, at once or (``standby``) once its holder ends; Refused: held
    elsewhere and not ``standby``. ``said(text)`` tells the operator."""
    if await locks.try_take(what):
        return
    holder = await locks.holder(what)
    if not standby:
        said(f"{what} is served by {holder}: one agent process each; not started")
        raise Refused(what)
    said(f"{what} is served by {holder}; standing by to take over when it ends")
    while True:
        await asyncio.sleep(STANDBY_POLL)
        try:
            if await locks.try_take(what):
                break
        except Exception as exc:  # its database connection gone: started again, it stands by
            raise LockLost(f"the database connection of its standby failed: {exc}") from exc
    said(f"{what}: took over (the process that served it ended)")
