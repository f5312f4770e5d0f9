"""Reasons stored in English (a run's wait for a share, a pruned log's quota: data, like the
run's log) are shown in the reader's language, and a share wait on a run's page is said to
its owner or, for a teacher, about them. Seen in pt-BR screenshots of issue 28's pages: the
Portuguese pages said "waiting: you already have 2 runs going" and "run log quota reached",
and a teacher's view of a student's queued run said "you already have"."""

import pytest
from django.contrib.auth.models import User
from django.test import Client
from django.utils import timezone

from programs.models import Program, Run
from robots import fair_shares
from robots.models import Robot
from runlogs import quota

pytestmark = pytest.mark.django_db

PORTUGUESE = {"HTTP_ACCEPT_LANGUAGE": "pt-BR"}


@pytest.fixture
def people():
    return User.objects.create_user("ana"), User.objects.create_superuser("prof")


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


def a_run(owner, **fields) -> Run:
    robot, _ = Robot.objects.get_or_create(name="arm", url="sim://")
    program, _ = Program.objects.get_or_create(owner=owner, name="p", language="python")
    run = Run.create_for(program, robot, owner)
    Run.objects.filter(pk=run.pk).update(**fields)
    return run


def test_a_share_wait_on_a_run_page_is_in_portuguese_and_said_to_whom_it_concerns(people):
    ana, prof = people
    run = a_run(ana)
    Run.enqueue(run.pk, fair_shares.user_reason(2, 2))

    mine = signed_in(ana).get(f"/runs/{run.pk}/", **PORTUGUESE).content.decode()
    assert "esperando: você já tem 2 execuções em andamento (seu limite é 2)" in mine
    assert "waiting:" not in mine
    theirs = signed_in(prof).get(f"/runs/{run.pk}/").content.decode()
    assert "waiting: its owner already has 2 runs going (their limit is 2)" in theirs
    assert "you already have" not in theirs


def test_a_robots_limit_in_the_queue_is_in_portuguese(people):
    ana, _ = people
    run = a_run(ana)
    Run.enqueue(run.pk, fair_shares.robot_reason(1))
    line = signed_in(ana).get("/robots/arm/queue", **PORTUGUESE).content.decode()
    assert "esperando: o robô executa no máximo 1 programa ao mesmo tempo" in line


def test_a_pruned_logs_note_and_download_say_the_quota_in_portuguese(people):
    ana, _ = people
    run = a_run(
        ana,
        state=Run.State.FINISHED,
        log_pruned_at=timezone.now(),
        log_pruned_reason=quota.user_reason(512 * 1024),
    )
    client = signed_in(ana)
    page = client.get(f"/runs/{run.pk}/", **PORTUGUESE).content.decode()
    words = "cota de registros de execução atingida (0,5 MB para os registros de cada usuário"
    assert words in page and "quota reached" not in page
    download = client.get(f"/runs/{run.pk}/log", **PORTUGUESE)
    assert download.status_code == 410 and words in download.content.decode()


def test_the_account_page_writes_megabytes_with_the_readers_decimal_comma(people, settings):
    ana, _ = people
    settings.RUN_LOG_QUOTA_PER_USER = 3 * 1024 * 1024
    a_run(ana, state=Run.State.FINISHED, log_bytes=1536 * 1024)
    page = signed_in(ana).get("/accounts/", **PORTUGUESE).content.decode()
    assert "Registros de execução: 1,5 MB de 3,0 MB" in page
