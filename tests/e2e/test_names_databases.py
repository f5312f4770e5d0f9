"""A name with a control character is a 422 on a real server, on SQLite (embedded) and on
PostgreSQL (split), which cannot store NUL at all: a 500 there before (issue 28, item 6).
The calls are tests/test_names.py's, every one that takes a name."""

import re

from tests.test_names import BAD, calls, says_which_character


def test_a_name_with_nul_is_a_422_on_either_database(any_appliance):
    app = any_appliance
    program = app.create_program("p", "print(1)\n")
    assert app.api("POST", "/api/groups", {"name": "class-a"}).status_code in (201, 409)
    session = app.session()  # /api/tokens: a session's only, with its CSRF token
    csrf = {"X-CSRFToken": session.cookies["csrftoken"]}
    wrong = []
    for method, path, body in calls(program["id"]):
        if path == "/api/tokens":
            response = session.request(method, path, json=body, headers=csrf)
        else:
            response = app.api(method, path, body)
        if response.status_code != 422 or not says_which_character(response.json(), BAD):
            wrong.append((method, path, response.status_code, response.text[:200]))
    assert not wrong, wrong
    names = [p["name"] for p in app.api("GET", "/api/programs").json()]
    assert not [name for name in names if re.search(r"[\x00-\x1f]", name)]


def test_the_pages_take_a_name_with_nul_without_a_server_error(any_appliance):
    """Forms that look a name up (a program's robot, its share target): no robot or user is
    so named, said as such, on either database."""
    app = any_appliance
    program = app.create_program("q", "print(1)\n")
    session = app.session()
    csrf = {"X-CSRFToken": session.cookies["csrftoken"]}
    run = session.post(f"/programs/{program['id']}/run", data={"robot": BAD}, headers=csrf)
    assert run.status_code == 404, run.text[:300]
    share = session.post(f"/programs/{program['id']}/shares/", data={"target": BAD}, headers=csrf)
    assert share.status_code == 200 and "U+0000" in share.text, share.text[:300]
