"""Numbers a page's form or link carries, as a student may edit them: digits that are not
ASCII ("²", "١") pass str.isdigit(), which int() refuses or reads otherwise. Each is a
clear refusal or ignored, never a server error."""

import pytest
from django.contrib.auth.models import User

from programs.models import Program
from robots.models import Robot, RobotButton

pytestmark = pytest.mark.django_db

ODD = ["²", "١٢", "1²", "99999999999999999999999", "-1", " 3"]


@pytest.fixture
def anna(client):
    user = User.objects.create_user("anna")
    client.force_login(user)
    return user


@pytest.fixture
def program(anna):
    program = Program.objects.create(owner=anna, name="p", language="python")
    program.save_source("print(1)\n", anna)
    return program


@pytest.mark.parametrize("base", ODD)
def test_a_draft_or_a_save_with_an_odd_base_revision(client, program, base):
    form = {"source": "print(2)\n", "language": "python", "base_revision": base}
    assert client.post(f"/programs/{program.pk}/draft", form).status_code == 204
    saved = client.post(f"/programs/{program.pk}/", {**form, "action": "save"})
    assert saved.status_code in (200, 302), saved.status_code
    for url in (f"/programs/{program.pk}/save", f"/programs/{program.pk}/start"):
        response = client.post(url, {**form, "robot": "nowhere"})
        assert response.status_code < 500, (url, response.status_code)
        assert "invalid literal" not in response.content.decode()


@pytest.mark.parametrize("edit", ["abc", "²", "1.5"])
def test_the_buttons_page_with_an_odd_button_number_is_not_found(client, anna, edit):
    robot = Robot.objects.create(name="rover", url="sim://", owner=anna)
    program = Program.objects.create(owner=anna, name="Dock", language="python")
    RobotButton.objects.create(robot=robot, label="Dock", program=program)
    assert client.get(f"/robots/rover/buttons/?edit={edit}").status_code == 404
