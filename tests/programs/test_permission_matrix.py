"""Who may list, read, edit, run, stop and share what: issue 7's permission matrix.

Every cell of the tables below is its own test: (scenario, actor, action, surface). The
actors are student A (class-a), student B (class-b), TA (teacher of class-a, through
robotide.models.ClassTeacher), TB (teacher of class-b), an admin (superuser) and an anonymous
visitor. A owns program P and has a run R of it on the robot ``sim``. The surfaces are the
pages (Django's test client, as a scripts-off browser), the API (/api/, session-signed) and the
run's websocket (RunConsumer through channels' WebsocketCommunicator).

The expected outcomes follow programs/access.py:

- a program is seen by its owner, whoever a share covers, the teachers of a class its *owner*
  belongs to, and admins; edited by its owner, an editable share's targets and admins; shared
  by its owner and admins only. Who sees it but may not do a thing gets 403; who may not see
  it, 404 (and it is missing from their list).
- a run (R, and its websocket) is seen by who started it, the teachers of that person's
  classes and admins -- sharing the *program* gives nobody its owner's runs.

The scenarios: ``private`` (P not shared), ``user-read`` (shared with B read-only),
``user-edit`` (shared with B, may edit), ``class-b`` (shared with the class class-b),
``everyone`` (shared with everyone), ``unshared`` (shared with B, then the share DELETEd
through the API: exactly ``private`` again).

Why TB sees nothing in ``class-b``: a group share covers the group's *members*
(``shares__group__in=user.groups``); TB is class-b's teacher through ClassTeacher, not a member
of the group, and the teacher rule (``owner__groups__in=taught_groups``) covers programs whose
*owner* is in a taught class -- A is in class-a, so P is not one of them. B, a member, reads it.
"""

import re

import pytest
from asgiref.sync import async_to_sync
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import AnonymousUser, Group, User
from django.test import Client

from programs.consumers import RunConsumer
from programs.models import Program, Run, Share
from programs.shares import add_share
from robotide.models import ClassTeacher
from robots.models import Robot

pytestmark = pytest.mark.django_db

SOURCE = "print('hello')\n"

# Outcomes: OK (allowed), NO (not seen: 404 / not in the list), RO (seen but forbidden: 403),
# IN (anonymous: sign in first -- 401 from the API, 302 to the login page, websocket refused).
OK, NO, RO, IN = "ok", "hidden", "forbidden", "sign-in"

ACTIONS = ("list", "read", "edit", "run", "stop", "share")
ACTORS = ("A", "B", "TA", "TB", "admin", "anon")

# fmt: off
# Per scenario, per actor: the outcome of each action, the same on the page and in the API
# (each cell is tested on both). The websocket's cells are in WEBSOCKET, below.
MATRIX = {
    "private": {
        #         list read edit run  stop share
        "A":     (OK,  OK,  OK,  OK,  OK,  OK),
        "B":     (NO,  NO,  NO,  NO,  NO,  NO),
        "TA":    (OK,  OK,  RO,  OK,  OK,  RO),
        "TB":    (NO,  NO,  NO,  NO,  NO,  NO),
        "admin": (OK,  OK,  OK,  OK,  OK,  OK),
        "anon":  (IN,  IN,  IN,  IN,  IN,  IN),
    },
    "user-read": {
        "A":     (OK,  OK,  OK,  OK,  OK,  OK),
        "B":     (OK,  OK,  RO,  OK,  NO,  RO),
        "TA":    (OK,  OK,  RO,  OK,  OK,  RO),
        "TB":    (NO,  NO,  NO,  NO,  NO,  NO),
        "admin": (OK,  OK,  OK,  OK,  OK,  OK),
        "anon":  (IN,  IN,  IN,  IN,  IN,  IN),
    },
    "user-edit": {
        "A":     (OK,  OK,  OK,  OK,  OK,  OK),
        "B":     (OK,  OK,  OK,  OK,  NO,  RO),
        "TA":    (OK,  OK,  RO,  OK,  OK,  RO),
        "TB":    (NO,  NO,  NO,  NO,  NO,  NO),
        "admin": (OK,  OK,  OK,  OK,  OK,  OK),
        "anon":  (IN,  IN,  IN,  IN,  IN,  IN),
    },
    "class-b": {
        "A":     (OK,  OK,  OK,  OK,  OK,  OK),
        "B":     (OK,  OK,  RO,  OK,  NO,  RO),
        "TA":    (OK,  OK,  RO,  OK,  OK,  RO),
        "TB":    (NO,  NO,  NO,  NO,  NO,  NO),   # a teacher, not a member: see the docstring
        "admin": (OK,  OK,  OK,  OK,  OK,  OK),
        "anon":  (IN,  IN,  IN,  IN,  IN,  IN),
    },
    "everyone": {
        "A":     (OK,  OK,  OK,  OK,  OK,  OK),
        "B":     (OK,  OK,  RO,  OK,  NO,  RO),
        "TA":    (OK,  OK,  RO,  OK,  OK,  RO),
        "TB":    (OK,  OK,  RO,  OK,  NO,  RO),
        "admin": (OK,  OK,  OK,  OK,  OK,  OK),
        "anon":  (IN,  IN,  IN,  IN,  IN,  IN),   # everyone means everyone signed in
    },
}
MATRIX["unshared"] = MATRIX["private"]

# R's websocket: who started R (A), A's teachers, admins -- in every scenario.
WEBSOCKET = {"A": OK, "B": NO, "TA": OK, "TB": NO, "admin": OK, "anon": IN}
# fmt: on

# Cells the app gets wrong, with why: {(scenario, actor, action, surface): reason}.
KNOWN_WRONG: dict[tuple, str] = {}


def cells():
    for scenario, rows in MATRIX.items():
        for actor in ACTORS:
            for action, expected in zip(ACTIONS, rows[actor], strict=True):
                for surface in ("page", "api"):
                    key = (scenario, actor, action, surface)
                    marks = []
                    if key in KNOWN_WRONG:
                        marks = [pytest.mark.xfail(strict=True, reason=KNOWN_WRONG[key])]
                    yield pytest.param(
                        *key, expected, marks=marks, id=f"{scenario}-{actor}-{action}-{surface}"
                    )


def websocket_cells():
    for scenario in MATRIX:
        for actor in ACTORS:
            yield pytest.param(
                scenario, actor, WEBSOCKET[actor], id=f"{scenario}-{actor}-run-stream"
            )


# -- the world ---------------------------------------------------------------------------


class World:
    def __init__(self):
        self.class_a = Group.objects.create(name="class-a")
        self.class_b = Group.objects.create(name="class-b")
        self.users = {
            "A": User.objects.create_user("anna", password="pw-anna-123"),
            "B": User.objects.create_user("ben", password="pw-ben-123"),
            "TA": User.objects.create_user("tess", password="pw-tess-123", is_staff=True),
            "TB": User.objects.create_user("theo", password="pw-theo-123", is_staff=True),
            "admin": User.objects.create_superuser("root", password="pw-root-123"),
            "anon": AnonymousUser(),
        }
        # Someone in no class, to share with in the "share" cells.
        self.carol = User.objects.create_user("carol", password="pw-carol-123")
        self.users["A"].groups.add(self.class_a)
        self.users["B"].groups.add(self.class_b)
        ClassTeacher.objects.create(group=self.class_a, user=self.users["TA"])
        ClassTeacher.objects.create(group=self.class_b, user=self.users["TB"])
        self.sim = Robot.objects.create(name="sim", url="sim://")
        self.program = Program.objects.create(
            owner=self.users["A"], name="secret plan", language="python"
        )
        self.program.save_source(SOURCE, self.users["A"])
        self.run = Run.create_for(self.program, self.sim, self.users["A"])

    def client(self, actor: str) -> Client:
        client = Client()
        if actor != "anon":
            client.force_login(self.users[actor])
        return client

    def share(self, scenario: str) -> None:
        owner, program = self.users["A"], self.program
        if scenario == "user-read":
            add_share(program, owner, user="ben")
        elif scenario == "user-edit":
            add_share(program, owner, user="ben", can_edit=True)
        elif scenario == "class-b":
            add_share(program, owner, group="class-b")
        elif scenario == "everyone":
            add_share(program, owner, everyone=True)
        elif scenario == "unshared":
            share = add_share(program, owner, user="ben", can_edit=True)
            response = self.client("A").delete(f"/api/programs/{program.pk}/shares/{share.pk}")
            assert response.status_code == 204
            assert not program.shares.exists()


@pytest.fixture
def world(monkeypatch):
    # New accounts' example programs (twenty-odd each) matter to none of these cells.
    monkeypatch.setattr("programs.signals.create_examples", lambda user: None)
    return World()


def api(client: Client, method: str, path: str, body=None):
    return getattr(client, method)(path, body, content_type="application/json")


# -- doing each action on each surface ---------------------------------------------------


def do(world: World, actor: str, action: str, surface: str):
    """Does ``action`` to P (or R) as ``actor`` on ``surface``: the response, and for "list"
    whether P was in the list."""
    client, pk, run = world.client(actor), world.program.pk, world.run.pk
    page = surface == "page"
    if action == "list":
        if page:
            response = client.get("/programs/")
            listed = response.status_code == 200 and "secret plan" in response.content.decode()
        else:
            response = client.get("/api/programs")
            listed = response.status_code == 200 and pk in {p["id"] for p in response.json()}
        return response, listed
    if action == "read":
        return client.get(f"/programs/{pk}/" if page else f"/api/programs/{pk}"), None
    if action == "edit":
        if page:
            data = {"action": "save", "language": "python", "source": "print('edited')\n"}
            return client.post(f"/programs/{pk}/", data), None
        return api(client, "put", f"/api/programs/{pk}", {"source": "print('edited')\n"}), None
    if action == "run":
        if page:
            return client.post(f"/programs/{pk}/run", {"robot": "sim"}), None
        return api(client, "post", f"/api/programs/{pk}/run", {"robot": "sim"}), None
    if action == "stop":
        return client.post(f"/runs/{run}/stop" if page else f"/api/runs/{run}/stop"), None
    if action == "share":
        if page:
            return client.post(f"/programs/{pk}/shares/", {"target": "user:carol"}), None
        return api(client, "post", f"/api/programs/{pk}/shares", {"user": "carol"}), None
    raise AssertionError(action)


def outcome(world: World, action: str, surface: str, response, listed) -> str:
    """What the response says happened, as one of OK, NO, RO, IN."""
    status = response.status_code
    location = response.get("Location", "")
    if surface == "api" and status == 401:
        return IN
    if surface == "page" and status == 302 and location.startswith("/accounts/login/"):
        return IN
    if status == 404:
        return NO
    if status == 403:
        return RO
    if action == "list":
        assert status == 200
        return OK if listed else NO
    pk = world.program.pk
    if surface == "page":
        expected = {
            "read": (200, ""),
            "edit": (302, f"/programs/{pk}/"),
            "run": (302, r"/runs/\d+/"),  # the run is made; its hand-off to the agent waits
            "stop": (302, f"/runs/{world.run.pk}/"),
            "share": (302, f"/programs/{pk}/"),
        }[action]
        assert status == expected[0], (status, response.content[:500])
        assert re.fullmatch(expected[1], location) or not expected[1], location
    else:
        # stop: allowed is "not 403/404"; with no agent the stop may also be 503.
        allowed = {"read": {200}, "edit": {200}, "run": {201}, "stop": {200, 503}, "share": {201}}
        assert status in allowed[action], (status, response.content[:500])
    return OK


def effect_seen(world: World, actor: str, action: str, result: str) -> None:
    """The database agrees with the answer: nothing changes behind a refusal."""
    program = Program.objects.get(pk=world.program.pk)
    if action == "edit":
        assert (program.source == "print('edited')\n") == (result == OK)
    if action == "share":
        assert Share.objects.filter(program=program, user=world.carol).exists() == (result == OK)
    if action == "run":
        runs = Run.objects.filter(program=program).exclude(pk=world.run.pk)
        if result == OK:
            assert runs.get().owner == world.users[actor]
        else:
            assert not runs.exists()


@pytest.mark.parametrize(("scenario", "actor", "action", "surface", "expected"), list(cells()))
def test_cell(
    world, scenario, actor, action, surface, expected, django_capture_on_commit_callbacks
):
    world.share(scenario)
    # The hand-off to the (absent) agent is on_commit: captured, not executed.
    with django_capture_on_commit_callbacks(execute=False):
        response, listed = do(world, actor, action, surface)
    result = outcome(world, action, surface, response, listed)
    assert result == expected, f"{actor} {action} on the {surface}: {result}, not {expected}"
    effect_seen(world, actor, action, result)


# -- the websocket -----------------------------------------------------------------------


async def _connects(user, run_id: int) -> bool:
    comm = WebsocketCommunicator(RunConsumer.as_asgi(), f"/ws/runs/{run_id}/")
    comm.scope["user"] = user
    comm.scope["url_route"] = {"kwargs": {"run_id": run_id}}
    connected, _ = await comm.connect()
    if connected:
        await comm.disconnect()
    return connected


def connects(user, run_id: int) -> bool:
    return async_to_sync(_connects)(user, run_id)


@pytest.mark.django_db(transaction=True)
@pytest.mark.parametrize(("scenario", "actor", "expected"), list(websocket_cells()))
def test_run_stream_cell(world, scenario, actor, expected):
    world.share(scenario)
    assert connects(world.users[actor], world.run.pk) == (expected == OK)


def test_the_matrix_has_every_cell():
    assert len(list(cells())) == len(MATRIX) * len(ACTORS) * len(ACTIONS) * 2
    assert len(list(websocket_cells())) == len(MATRIX) * len(ACTORS)


def test_an_editor_edits_the_source_but_renames_nothing(world):
    """Renaming is its owner's and admins' (programs/access.py): B, who may edit P, renamed it
    through the API, and the 409 of a name A already had told B A's private programs' names."""
    Program.objects.create(owner=world.users["A"], name="my private exam answers")
    world.share("user-edit")
    b, pk = world.client("B"), world.program.pk
    for name in ("renamed by ben", "my private exam answers"):
        response = api(b, "put", f"/api/programs/{pk}", {"name": name})
        assert response.status_code == 403, (name, response.content)
        assert "exam" not in response.content.decode()
    assert api(b, "put", f"/api/programs/{pk}", {"source": "print('ben')\n"}).status_code == 200
    same = api(b, "put", f"/api/programs/{pk}", {"name": "secret plan", "source": SOURCE})
    assert same.status_code == 200, same.content  # its own name again is no renaming
    world.program.refresh_from_db()
    assert world.program.name == "secret plan" and world.program.source == SOURCE
    owner = api(world.client("A"), "put", f"/api/programs/{pk}", {"name": "plan B"})
    assert owner.status_code == 200


# -- unsharing takes access away at once -------------------------------------------------


@pytest.mark.django_db(transaction=True)
def test_unsharing_takes_access_away_at_once_but_leaves_runs_b_started(world):
    """B reads and runs P while it is shared; once A deletes the share, P is gone for B from
    the page, the API and the list, and B cannot run it -- but the run B started while it was
    shared stays B's own (runs_for_user: who started it), on the page, the API and its
    websocket. A's run R was never B's to see."""
    a, b = world.client("A"), world.client("B")
    pk = world.program.pk
    created = api(a, "post", f"/api/programs/{pk}/shares", {"user": "ben"})
    assert created.status_code == 201 and created.json()["user"] == "ben"
    assert b.get(f"/programs/{pk}/").status_code == 200
    started = api(b, "post", f"/api/programs/{pk}/run", {"robot": "sim"})
    assert started.status_code == 201
    bens_run = started.json()["id"]
    assert started.json()["owner"] == "ben"

    assert a.delete(f"/api/programs/{pk}/shares/{created.json()['id']}").status_code == 204

    assert b.get(f"/programs/{pk}/").status_code == 404
    assert b.get(f"/api/programs/{pk}").status_code == 404
    assert pk not in {p["id"] for p in b.get("/api/programs").json()}
    assert "secret plan" not in b.get("/programs/").content.decode()
    assert api(b, "post", f"/api/programs/{pk}/run", {"robot": "sim"}).status_code == 404
    assert b.post(f"/programs/{pk}/run", {"robot": "sim"}).status_code == 404
    assert not connects(world.users["B"], world.run.pk)
    # B's own run of P is still B's.
    assert b.get(f"/api/runs/{bens_run}").status_code == 200
    assert b.get(f"/runs/{bens_run}/").status_code == 200
    assert connects(world.users["B"], bens_run)
    # ... and still A's teacher's? No: it is B's, so B's teacher (TB) and admins see it.
    assert world.client("TB").get(f"/api/runs/{bens_run}").status_code == 200
    assert world.client("TA").get(f"/api/runs/{bens_run}").status_code == 404


def test_unsharing_on_the_page_takes_access_away(world):
    a, b = world.client("A"), world.client("B")
    pk = world.program.pk
    shared = a.post(f"/programs/{pk}/shares/", {"target": "user:ben"})
    assert shared.status_code == 302
    share = world.program.shares.get()
    assert b.get(f"/programs/{pk}/").status_code == 200
    # Only the owner unshares: B (who sees it) is refused, TB (who does not) gets 404.
    assert b.post(f"/programs/{pk}/shares/{share.pk}/delete").status_code == 403
    assert world.client("TB").post(f"/programs/{pk}/shares/{share.pk}/delete").status_code == 404
    assert api(b, "delete", f"/api/programs/{pk}/shares/{share.pk}").status_code == 403
    assert a.post(f"/programs/{pk}/shares/{share.pk}/delete").status_code == 302
    assert not world.program.shares.exists()
    assert b.get(f"/programs/{pk}/").status_code == 404


# -- robots restricted to a class --------------------------------------------------------

# fmt: off
#                 listed(api) listed(page) detail(api) detail(page) run(api) run(page)
ROBOT_MATRIX = {
    "A":     (OK,  OK,  OK,  OK,  OK,  OK),
    "B":     (NO,  NO,  NO,  NO,  NO,  NO),
    "TA":    (OK,  OK,  OK,  OK,  OK,  OK),
    "TB":    (NO,  NO,  NO,  NO,  NO,  NO),
    "admin": (OK,  OK,  OK,  OK,  OK,  OK),
    "anon":  (IN,  IN,  IN,  IN,  IN,  IN),
}
# fmt: on
ROBOT_ACTIONS = ("list-api", "list-page", "detail-api", "detail-page", "run-api", "run-page")


def robot_cells():
    for actor, row in ROBOT_MATRIX.items():
        for action, expected in zip(ROBOT_ACTIONS, row, strict=True):
            yield pytest.param(actor, action, expected, id=f"lab-robot-{actor}-{action}")


@pytest.mark.parametrize(("actor", "action", "expected"), list(robot_cells()))
def test_robot_of_a_class_cell(world, actor, action, expected, django_capture_on_commit_callbacks):
    """The robot ``lab`` belongs to class-a: its members, its teachers and admins use it; B
    and TB neither see it nor start a run on it, even of a program they may run (their own)."""
    lab = Robot.objects.create(name="lab", url="sim://")
    lab.groups.add(world.class_a)
    client = world.client(actor)
    user = world.users[actor]
    # A program the actor may certainly run: their own (anon: A's).
    own = world.program
    if user.is_authenticated and actor != "A":
        own = Program.objects.create(owner=user, name="mine", language="python")
        own.save_source(SOURCE, user)
    with django_capture_on_commit_callbacks(execute=False):
        if action == "list-api":
            response = client.get("/api/robots")
            listed = response.status_code == 200 and "lab" in {r["name"] for r in response.json()}
        elif action == "list-page":
            response = client.get("/robots/")
            listed = response.status_code == 200 and "/robots/lab/" in response.content.decode()
        elif action == "detail-api":
            response = client.get("/api/robots/lab")
        elif action == "detail-page":
            response = client.get("/robots/lab/")  # no agent: waits its 1 s for the state
        elif action == "run-api":
            response = api(client, "post", f"/api/programs/{own.pk}/run", {"robot": "lab"})
        else:
            response = client.post("/robots/lab/run", {"program": own.pk})
    status = response.status_code
    if status == 401 or (status == 302 and response["Location"].startswith("/accounts/login/")):
        result = IN
    elif status == 404:
        result = NO
    elif action.startswith("list"):
        assert status == 200
        result = OK if listed else NO
    else:
        assert status in {200, 201, 302}, status
        if action == "run-page":
            assert re.fullmatch(r"/runs/\d+/", response["Location"])
        result = OK
    assert result == expected
    made = Run.objects.filter(robot=lab)
    if action.startswith("run"):
        assert made.exists() == (result == OK)
        if result == OK:
            assert made.get().owner == user
