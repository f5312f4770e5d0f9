"""Log storage on the database and files alone: what a running log is granted,
whose logs are pruned for the total, that two running logs never count on the same free bytes,
that only logs are ever deleted, and that pruning never races a reader or a compression."""

import base64
import os

import pytest
from asgiref.sync import async_to_sync
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import User
from django.test import Client
from django.utils import timezone

from programs.consumers import RunConsumer
from programs.models import Program, Revision, Run
from programs.runlog import read_for_page
from robots.models import Robot
from runlogs import files, quota, writer

pytestmark = pytest.mark.django_db

MB = 1024 * 1024


@pytest.fixture
def quotas(settings):
    settings.RUN_LOG_QUOTA_PER_USER = 3 * MB
    settings.RUN_LOG_QUOTA_TOTAL = 4 * MB
    return settings


@pytest.fixture
def robot():
    return Robot.objects.create(name="sim", url="sim://")


def a_run(user, robot, size: int, *, state="finished", minutes_ago=0) -> Run:
    program, _ = Program.objects.get_or_create(owner=user, name="p", language="python")
    program.save_source("print(1)\n", user)
    run = Run.create_for(program, robot, user)
    run.log_path.parent.mkdir(parents=True, exist_ok=True)
    run.log_path.write_bytes(b"o " + b"x" * (size - 3) + b"\n" if size else b"")
    ended = timezone.now() - timezone.timedelta(minutes=minutes_ago)
    Run.objects.filter(pk=run.pk).update(
        state=state, log_bytes=size, ended=None if state in Run.ONGOING else ended
    )
    run.refresh_from_db()
    return run


def test_the_total_prunes_the_oldest_ended_logs_of_anybody_and_nothing_else(quotas, robot):
    ann, bob = User.objects.create_user("ann"), User.objects.create_user("bob")
    oldest = a_run(bob, robot, MB, minutes_ago=30)
    older = a_run(ann, robot, MB, minutes_ago=20)
    running = a_run(bob, robot, MB, state="running")
    flood = a_run(ann, robot, 0, state="running")
    made = Program.objects.count(), Revision.objects.count(), Run.objects.count()

    # 1.5 MB more: within ann's 3 MB, not within 4 MB in all: the oldest of anybody goes.
    assert quota.grant(flood.pk, 0, MB + MB // 2, 64 * MB) == quota.Grant(MB + MB // 2)
    oldest.refresh_from_db()
    assert (
        oldest.log_pruned_at is not None and "4 MB for all users' logs" in oldest.log_pruned_reason
    )
    assert not files.exists(oldest.log_path)
    for kept in (older, running):
        kept.refresh_from_db()
        assert kept.log_pruned_at is None and files.exists(kept.log_path)

    # 1 MB more: beyond ann's 3 MB with her older log: it goes.
    assert quota.grant(flood.pk, MB + MB // 2, MB, 64 * MB) == quota.Grant(2 * MB + MB // 2)
    older.refresh_from_db()
    assert older.log_pruned_at is not None and "3 MB for a user's logs" in older.log_pruned_reason

    # Nothing ended is left to prune: what is left is all a running log gets, then no more.
    refused = quota.grant(flood.pk, 2 * MB + MB // 2, MB, 64 * MB)
    assert refused.limit == 3 * MB and "3 MB for a user's logs" in refused.refused
    refused = quota.grant(running.pk, MB, MB, 64 * MB)  # bob's: 1 MB + ann's 3 MB is 4 MB
    assert refused.limit == MB and "4 MB for all users' logs" in refused.refused
    running.refresh_from_db()
    assert running.log_pruned_at is None and files.exists(running.log_path)
    assert (Program.objects.count(), Revision.objects.count(), Run.objects.count()) == made


def test_two_running_logs_never_count_on_the_same_bytes(quotas, robot):
    ann = User.objects.create_user("ann")
    first, second = a_run(ann, robot, 0, state="running"), a_run(ann, robot, 0, state="running")
    limits = {first.pk: 0, second.pk: 0}
    for _ in range(100):  # by turns, as two floods ask
        for run in (first, second):
            answer = quota.grant(run.pk, limits[run.pk], 1, 64 * MB)
            if not answer.refused:
                limits[run.pk] = answer.limit
    assert sum(limits.values()) == 3 * MB
    assert quota.usage_of(ann).used == 0  # nothing written yet: the page counts what is


def test_a_page_made_while_its_log_is_pruned_says_so(quotas, robot):
    ann = User.objects.create_user("ann")
    run = a_run(ann, robot, 1000)
    page_run = Run.objects.get(pk=run.pk)  # read before the log went
    with quota.quota_lock():
        quota.prune(run.pk, quota.user_reason(3 * MB))
    assert read_for_page(page_run) == ([], 0, 0)
    assert page_run.log_pruned_at is not None

    client = Client()
    client.force_login(ann)
    page = client.get(f"/runs/{run.pk}/")
    assert page.status_code == 200 and b'id="log-pruned"' in page.content
    assert b"Download log" not in page.content
    gone = client.get(f"/runs/{run.pk}/log")
    assert gone.status_code == 410 and b"3 MB for a user" in gone.content


def test_a_log_pruned_while_it_was_compressed_stays_pruned(quotas, robot):
    ann = User.objects.create_user("ann")
    run = a_run(ann, robot, 5000)
    part = files.compress_aside(run.log_path)
    with quota.quota_lock():
        quota.prune(run.pk, quota.user_reason(3 * MB))
    assert quota.put_compressed(run.pk, part) is False
    assert not files.exists(run.log_path) and not part.exists()


def test_the_account_page_says_how_much_of_the_quota_is_used(quotas, robot):
    ann = User.objects.create_user("ann")
    a_run(ann, robot, MB + MB // 2)
    client = Client()
    client.force_login(ann)
    page = client.get("/accounts/")
    assert b"Run logs: 1.5 MB of 3.0 MB" in page.content


@pytest.mark.django_db(transaction=True)  # compress() asks the database as the agent does
def test_a_log_that_does_not_compress_is_kept_plain_and_not_tried_again(quotas, robot):
    quotas.RUN_LOG_COMPRESS_AFTER = 0.0
    ann = User.objects.create_user("ann")
    run = a_run(ann, robot, 10)
    noise = b"".join(b"o " + base64.b64encode(os.urandom(3000)) + b"\n" for _ in range(400))
    run.log_path.write_bytes(noise)  # what a flood of random bytes leaves
    assert run.pk in quota.due_for_compression()

    assert async_to_sync(writer.compress)(run.pk) is False
    run.refresh_from_db()
    assert run.log_storage == "plain" and run.log_path.read_bytes() == noise
    assert run.pk not in quota.due_for_compression()


@pytest.mark.django_db(transaction=True)
def test_the_run_websocket_sends_a_compressed_log_as_it_did_plain(quotas, robot):
    """Its tail and its catch-up from the offset a page was made with."""
    ann = User.objects.create_user("ann")
    run = a_run(ann, robot, 0)
    run.log_path.write_bytes(b"".join(b"o line %d\n" % n for n in range(30000)))
    offset = run.log_path.stat().st_size - len(b"o line 29999\n")

    def sent(path):
        async def connect():
            comm = WebsocketCommunicator(RunConsumer.as_asgi(), path)
            comm.scope["user"], comm.scope["url_route"] = ann, {"kwargs": {"run_id": run.pk}}
            assert (await comm.connect())[0]
            first = await comm.receive_from()
            await comm.disconnect()
            return first

        return async_to_sync(connect)()

    plain = sent(f"/ws/runs/{run.pk}/"), sent(f"/ws/runs/{run.pk}/?from={offset}")
    assert "28000 line(s) not shown live" in plain[0] and "line 29999" in plain[1]
    assert "line 29998" not in plain[1]
    async_to_sync(writer.compress)(run.pk)
    assert not run.log_path.exists()
    assert (sent(f"/ws/runs/{run.pk}/"), sent(f"/ws/runs/{run.pk}/?from={offset}")) == plain
