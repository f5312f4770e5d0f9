"""Run log quotas with a real agent (in this process) on a sim robot: log floods by one user
keep that user's logs within their quota, the oldest ended logs pruned first; another user's
logs are untouched; a pruned run's page, its API answer and its download say so; a log that
would outgrow what is left ends its run saying why; ended logs are compressed in the
background and read the same."""

import re

import pytest
from channels.db import database_sync_to_async
from django.test import Client

from programs.models import Run
from runlogs import files, quota
from tests.e2e.agents import finished, run_program, until

pytestmark = pytest.mark.django_db(transaction=True)

MB = 1024 * 1024
# Random text: it does not compress away, and it floods until a limit ends it.
FLOOD = """
import base64, os, sys
print("flood begins", flush=True)
while True:
    sys.stdout.write(base64.b64encode(os.urandom(3000)).decode() + "\\n")
"""
SAYS_HELLO = "print('hello from another user')\n"
MANY_LINES = """
import sys
for n in range(3000):
    print(f"line {n} " + "x" * (n % 70), flush=n % 500 == 0)
    if n % 700 == 0:
        print(f"warning {n}", file=sys.stderr)
"""


@pytest.fixture
def small_quotas(settings):
    """A user may keep 3 MB of logs, one run's log may be 1 MB; nothing compressed."""
    settings.RUN_LOG_QUOTA_PER_USER = 3 * MB
    settings.RUN_LOG_QUOTA_TOTAL = 1024 * MB
    settings.RUN_LOG_COMPRESS_AFTER = 3600.0
    settings.RUN_DEFAULTS = {**settings.RUN_DEFAULTS, "log_size_mb": 1}
    return settings


def on_disk(runs) -> int:
    return sum(files.disk_bytes(run.log_path) for run in runs)


@database_sync_to_async
def other_user(name: str):
    from django.contrib.auth.models import User

    return User.objects.create_user(name)


@database_sync_to_async
def get(user, path: str) -> tuple[int, bytes]:
    client = Client()
    client.force_login(user)
    response = client.get(path)
    body = b"".join(response.streaming_content) if response.streaming else response.content
    return response.status_code, body


@database_sync_to_async
def api_get(user, path: str) -> tuple[int, dict]:
    client = Client()
    client.force_login(user)
    response = client.get(path)
    return response.status_code, response.json()


async def ended_run(user, robot, source: str) -> Run:
    return await finished(await run_program(user, robot, source), timeout=60)


async def test_twenty_floods_keep_their_users_logs_within_the_quota(robot_on, small_quotas):
    _peer, _agent, robot, student = await robot_on("sim")
    classmate = await other_user("classmate")
    hers = await ended_run(classmate, robot, SAYS_HELLO)
    her_log = files.open_log(hers.log_path).file.read()

    floods = []
    for _ in range(20):
        floods.append(await ended_run(student, robot, FLOOD))
        assert on_disk(floods) <= 3 * MB  # after each: the quota holds, the run ended
    assert all("output size limit (1 MB)" in run.reason for run in floods)

    # The oldest went first; the newest are all there, none of them cut.
    for run in floods:
        await database_sync_to_async(run.refresh_from_db)()
    pruned = [run for run in floods if run.log_pruned_at is not None]
    kept = [run for run in floods if run.log_pruned_at is None]
    assert len(pruned) >= 17 and kept == floods[len(pruned) :]
    assert all(not files.exists(run.log_path) for run in pruned)
    assert all(files.disk_bytes(run.log_path) > MB - 64 * 1024 for run in kept)
    assert all("run log quota reached (3 MB for a user's logs" in run.log_pruned_reason
               for run in pruned)  # fmt: skip

    # The classmate's log is untouched.
    await database_sync_to_async(hers.refresh_from_db)()
    assert hers.log_pruned_at is None
    assert files.open_log(hers.log_path).file.read() == her_log

    # The pruned run's page, API answer and download say so; the kept one's page shows it.
    first = pruned[0]
    status, page = await get(student, f"/runs/{first.pk}/")
    assert status == 200
    assert b'id="log-pruned"' in page and b"was pruned on" in page
    assert b"3 MB for a user&#x27;s logs" in page
    status, answer = await api_get(student, f"/api/runs/{first.pk}")
    assert status == 200 and answer["log_pruned_at"] and "quota" in answer["log_pruned_reason"]
    status, body = await get(student, f"/runs/{first.pk}/log")
    assert status == 410 and b"was pruned on" in body
    status, page = await get(student, f"/runs/{floods[-1].pk}/")
    assert status == 200 and b"flood begins" in page and b'id="log-pruned"' not in page
    status, body = await get(student, f"/runs/{floods[-1].pk}/log")
    assert status == 200 and body.startswith(b"flood begins\n")

    # The account page says how much of the quota the logs take.
    status, page = await get(student, "/accounts/")
    assert status == 200 and b"Run logs:" in page and b"of 3.0 MB" in page


async def test_a_log_that_would_outgrow_what_is_left_ends_its_run(robot_on, settings):
    settings.RUN_LOG_QUOTA_PER_USER = 1 * MB
    settings.RUN_LOG_QUOTA_TOTAL = 1024 * MB
    settings.RUN_LOG_COMPRESS_AFTER = 3600.0
    _peer, _agent, robot, student = await robot_on("sim")  # a run's own cap: 64 MB

    run = await ended_run(student, robot, FLOOD)
    assert run.state == "failed" and "run log quota reached (1 MB" in run.reason
    assert files.disk_bytes(run.log_path) <= MB + 1024  # its own last line beyond it at most
    last = files.open_log(run.log_path).file.read().splitlines()[-3:]
    assert any(b"further output was discarded" in line for line in last), last

    # The next one has the first, ended, pruned to make room, and ends at the quota too.
    second = await ended_run(student, robot, FLOOD)
    assert "run log quota reached" in second.reason
    await database_sync_to_async(run.refresh_from_db)()
    assert run.log_pruned_at is not None


NUMBERED_FLOOD = """
import sys
n = 0
while True:
    sys.stdout.write(f"{n} " + "y" * 200 + "\\n")
    n += 1
"""


async def test_two_floods_at_once_share_what_is_left_and_lose_no_line_before_it(robot_on, settings):
    """Their output waits in its pipes while a grant is asked: each log is every line the
    program wrote, in order, up to where the quota ended it."""
    settings.RUN_LOG_QUOTA_PER_USER = 2 * MB
    settings.RUN_LOG_QUOTA_TOTAL = 1024 * MB
    settings.RUN_LOG_COMPRESS_AFTER = 3600.0
    _peer, _agent, robot, student = await robot_on("sim")
    runs = [await run_program(student, robot, NUMBERED_FLOOD) for _ in range(2)]
    runs = [await finished(run, timeout=60) for run in runs]
    assert all("run log quota reached (2 MB" in run.reason for run in runs), runs
    assert on_disk(runs) <= 2 * MB + 2 * (64 + 1) * 1024  # each: its first 64 KB unasked
    for run in runs:
        lines = files.open_log(run.log_path).file.read().splitlines()
        numbers = [int(line[2:].split(b" ")[0]) for line in lines if line.startswith(b"o ")]
        assert numbers == list(range(len(numbers))) and len(numbers) > 100
        assert lines[-2].startswith(b"s [robotide] run log quota reached"), lines[-3:]


async def test_ended_logs_are_compressed_in_the_background_and_read_the_same(
    robot_on, small_quotas
):
    _peer, _agent, robot, student = await robot_on("sim")
    run = await ended_run(student, robot, MANY_LINES)
    assert run.state == "finished"
    page_before = await get(student, f"/runs/{run.pk}/")
    download_before = await get(student, f"/runs/{run.pk}/log")
    api_before = await get(student, f"/api/runs/{run.pk}/log?stream=stderr")
    assert b"warning 2800" in download_before[1] and b"line 2999" in shown_log(page_before)
    assert b" earlier lines: download" in shown_log(page_before)  # a tail, not the whole log

    # From now on a log is compressed as its run ends: the next run's, and the first's with it.
    small_quotas.RUN_LOG_COMPRESS_AFTER = 0.0
    second = await ended_run(student, robot, SAYS_HELLO)
    for each in (run, second):
        await until(lambda each=each: files.gzipped(each.log_path).exists(), 30, "compressed")
        await until(lambda each=each: not each.log_path.exists(), 30, "plain log gone")

    await database_sync_to_async(run.refresh_from_db)()
    assert run.log_storage == "gzip" and run.log_bytes == files.gzipped(run.log_path).stat().st_size
    assert run.log_bytes < files.written_length(run.log_path) / 3
    assert shown_log(await get(student, f"/runs/{run.pk}/")) == shown_log(page_before)
    assert await get(student, f"/runs/{run.pk}/log") == download_before
    assert await get(student, f"/api/runs/{run.pk}/log?stream=stderr") == api_before
    assert (await quota_usage(student)).used == run.log_bytes + await settled_bytes(second)


def shown_log(page: tuple[int, bytes]) -> bytes:
    """The log lines a run page shows, and the offset its websocket goes on from."""
    status, html = page
    assert status == 200
    lines = html[html.index(b'<div id="log-lines">') : html.index(b"</pre>")]
    offset = re.search(rb"from=(\d+)", html)
    return lines + b"|from=" + (offset.group(1) if offset else b"?")


@database_sync_to_async
def quota_usage(user):
    return quota.usage_of(user)


@database_sync_to_async
def settled_bytes(run) -> int:
    run.refresh_from_db()
    return run.log_bytes
