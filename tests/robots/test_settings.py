"""Typed per-robot driver options: read off each driver, edited on the robot page, in the
admin and through the API, always checked by building the driver before they are saved."""

import pytest
from django.contrib.auth.models import User

import rhal
from rhal.options import driver_options
from robots.models import Robot
from tests.admin_inlines import no_inline_rows

pytestmark = pytest.mark.django_db


@pytest.fixture
def staff(client):
    user = User.objects.create_user("teacher", password="pw", is_staff=True, is_superuser=True)
    client.force_login(user)
    return user


@pytest.fixture
def robot():
    return Robot.objects.create(
        name="rover", url="sim://?arena=square", settings={"limits": {"cpu_seconds": 5}}
    )


@pytest.mark.parametrize("scheme", sorted(rhal.DRIVERS))
def test_every_driver_option_is_typed_and_explained(scheme):
    options = driver_options(f"{scheme}://")
    assert {"max_linear", "max_angular"} <= {o.name for o in options}
    for option in options:
        assert option.kind in (bool, int, float, str)
        assert option.help, f"{scheme}:// option {option.name} has no help text"
        assert option.default is None or isinstance(option.default, (option.kind, int))


def test_text_options_parse_as_the_driver_takes_them():
    by_name = {o.name: o for o in driver_options("dtmf://")}
    assert by_name["device"].parse("3") == 3  # a sound device's index
    assert by_name["device"].parse("USB Audio") == "USB Audio"
    assert by_name["wav"].parse(" ") is None
    assert by_name["table"].parse("forward:2") == "forward:2"


def test_the_robot_page_shows_each_option_and_where_it_comes_from(client, staff, robot):
    robot.settings["max_linear"] = 0.3
    robot.save()
    page = client.get(f"/robots/{robot.name}/").content.decode()
    assert '<code>arena</code></th><td>square</td><td class="source">from the URL' in page
    assert '<code>max_linear</code></th><td>0.3</td><td class="source">set here' in page
    assert '<code>max_angular</code></th><td>2.0</td><td class="source">default' in page


def test_staff_edit_options_and_only_changes_are_stored(client, staff, robot):
    form = client.get(f"/robots/{robot.name}/settings").content.decode()
    assert 'name="option_max_linear"' in form and 'name="option_arena"' in form
    response = client.post(
        f"/robots/{robot.name}/settings",
        {
            "url": robot.url,
            "option_arena": "square",
            "option_max_linear": "0.3",
            "option_max_angular": "2",
        },
    )
    assert response.status_code == 302
    robot.refresh_from_db()
    # The arena is what the URL says and the turn rate the default: neither is stored.
    assert robot.settings == {"limits": {"cpu_seconds": 5}, "max_linear": 0.3}


def test_a_bad_value_is_shown_at_its_field_and_nothing_is_saved(client, staff, robot):
    response = client.post(
        f"/robots/{robot.name}/settings",
        {"url": robot.url, "option_max_linear": "-1", "option_arena": "square"},
    )
    assert response.status_code == 200
    assert "max_linear must be greater than 0" in response.content.decode()
    robot.refresh_from_db()
    assert "max_linear" not in robot.settings


def test_a_value_of_the_wrong_type_is_refused_by_the_form(client, staff, robot):
    response = client.post(
        f"/robots/{robot.name}/settings", {"url": robot.url, "option_max_linear": "fast"}
    )
    assert "Enter a number." in response.content.decode()


def test_another_driver_starts_from_its_defaults(client, staff, robot):
    robot.settings["max_linear"] = 0.3
    robot.save()
    response = client.post(
        f"/robots/{robot.name}/settings",
        {"url": "pioneer+tcp://127.0.0.1:8101", "option_max_linear": "0.3"},
    )
    assert response.headers["Location"] == f"/robots/{robot.name}/settings"
    robot.refresh_from_db()
    assert robot.url == "pioneer+tcp://127.0.0.1:8101"
    assert robot.settings == {"limits": {"cpu_seconds": 5}}
    assert 'name="option_track"' in client.get(response.headers["Location"]).content.decode()


def test_an_unknown_driver_is_refused(client, staff, robot):
    response = client.post(f"/robots/{robot.name}/settings", {"url": "warp://x"})
    assert "no robot driver for" in response.content.decode()


def test_only_staff_edit_settings(client, robot):
    client.force_login(User.objects.create_user("student"))
    assert client.get(f"/robots/{robot.name}/settings").status_code == 302
    assert client.post(f"/robots/{robot.name}/settings", {"url": "sim://"}).status_code == 302
    robot.refresh_from_db()
    assert robot.url == "sim://?arena=square"


def test_the_admin_edits_the_same_typed_options(client, staff, robot):
    url = f"/admin/robots/robot/{robot.pk}/change/"
    page = client.get(url).content.decode()
    assert 'name="option_max_linear"' in page and 'name="run_settings"' in page
    response = client.post(
        url,
        {
            "name": robot.name,
            "url": robot.url,
            "description": "",
            "option_arena": "boxes",
            "option_max_linear": "0.25",
            "option_max_angular": "2.0",
            "run_settings": '{"limits": {"cpu_seconds": 9}}',
            **no_inline_rows(),
        },
    )
    assert response.status_code == 302, response.content.decode()
    robot.refresh_from_db()
    assert robot.settings == {"limits": {"cpu_seconds": 9}, "arena": "boxes", "max_linear": 0.25}


def test_the_admin_refuses_what_is_not_a_run_setting(client, staff, robot):
    response = client.post(
        f"/admin/robots/robot/{robot.pk}/change/",
        {
            "name": robot.name,
            "url": robot.url,
            "run_settings": '{"max_linear": 1}',
            **no_inline_rows(),
        },
    )
    assert "not a run setting: max_linear" in response.content.decode()


def test_the_api_changes_settings_and_checks_them(client, staff, robot):
    patch = "application/json"
    response = client.patch(
        f"/api/robots/{robot.name}", {"settings": {"max_linear": 0.2}}, content_type=patch
    )
    assert response.status_code == 200, response.content
    assert response.json()["settings"] == {"max_linear": 0.2}
    response = client.patch(
        f"/api/robots/{robot.name}", {"settings": {"max_linaer": 0.2}}, content_type=patch
    )
    assert response.status_code == 422
    assert "max_linaer" in response.json()["detail"]
    robot.refresh_from_db()
    assert robot.settings == {"max_linear": 0.2}


def test_only_staff_change_robots_through_the_api(client, robot):
    client.force_login(User.objects.create_user("student"))
    response = client.patch(
        f"/api/robots/{robot.name}", {"description": "mine"}, content_type="application/json"
    )
    assert response.status_code == 403


@pytest.mark.parametrize("body", ["[null, null]", '"x"', "3", "null"])
def test_a_change_that_is_not_an_object_is_refused(client, staff, robot, body):
    response = client.patch(f"/api/robots/{robot.name}", body, content_type="application/json")
    assert response.status_code == 422
    assert "the body must be a JSON object" in response.json()["detail"][0]["msg"]
