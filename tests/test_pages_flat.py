"""Staff pages (django.contrib.flatpages): in the menu, under /pages/, sanitised when shown."""

import re

import pytest
from django.contrib.auth.models import Permission, User
from django.contrib.flatpages.models import FlatPage
from django.contrib.sites.models import Site

pytestmark = pytest.mark.django_db


def make_page(url, title, content="<p>text</p>", registration_required=False):
    page = FlatPage.objects.create(
        url=url, title=title, content=content, registration_required=registration_required
    )
    page.sites.add(Site.objects.get(pk=1))
    return page


@pytest.fixture
def alice(client):
    user = User.objects.create_user("alice", password="pw-alice-123")
    client.force_login(user)
    return user


def test_pages_are_listed_in_the_menu(client, alice):
    make_page("/lab-rules/", "Lab rules")
    make_page("/wiring/", "Robot wiring", registration_required=True)
    menu = client.get("/programs/").content.decode()
    assert "<summary" in menu and ">Pages</summary>" in menu
    assert re.search(r'<a href="/pages/lab-rules/"[^>]*>Lab rules</a>', menu)
    assert re.search(r'<a href="/pages/wiring/"[^>]*>Robot wiring</a>', menu)


def test_no_pages_no_menu_entry(client, alice):
    assert "Pages</summary>" not in client.get("/programs/").content.decode()


def test_a_page_is_shown_sanitised(client, alice):
    make_page(
        "/lab-rules/",
        "Lab <b>rules</b>",
        '<h2>Safety</h2><p onclick="steal()" style="color:red">Stop the robot first.</p>'
        '<script>alert(1)</script><a href="javascript:alert(2)">x</a>'
        '<img src="/static/wiring.png" onerror="alert(3)"><a href="/programs/">programs</a>',
    )
    response = client.get("/pages/lab-rules/")
    assert response.status_code == 200
    html = response.content.decode()
    article = html.split('<article class="flatpage">', 1)[1].split("</article>", 1)[0]
    assert "<h2>Safety</h2>" in article and "<p>Stop the robot first.</p>" in article
    assert '<a href="/programs/" rel="noopener noreferrer">programs</a>' in article
    assert '<img src="/static/wiring.png">' in article
    for bad in ("<script", "alert", "onclick", "onerror", "style=", "javascript:"):
        assert bad not in article
    assert "<h1>Lab &lt;b&gt;rules&lt;/b&gt;</h1>" in html
    assert "<title>Lab &lt;b&gt;rules&lt;/b&gt; · robotide</title>" in html


def test_a_page_for_signed_in_users_only(client):
    make_page("/wiring/", "Robot wiring", registration_required=True)
    make_page("/open/", "Open day")
    response = client.get("/pages/wiring/")
    assert response.status_code == 302 and response["Location"].startswith("/accounts/login/")
    assert client.get("/pages/open/").status_code == 200
    assert client.get("/pages/nope/").status_code == 404


def test_staff_with_the_permission_edit_pages_in_the_admin(client):
    page = make_page("/lab-rules/", "Lab rules")
    staff = User.objects.create_user("teacher", password="pw-teacher-123", is_staff=True)
    staff.user_permissions.add(*Permission.objects.filter(content_type__app_label="flatpages"))
    client.force_login(staff)
    assert client.get("/admin/flatpages/flatpage/add/").status_code == 200
    shown = client.get("/pages/lab-rules/").content.decode()
    assert f'href="/admin/flatpages/flatpage/{page.pk}/change/">Edit</a>' in shown
    response = client.post(
        f"/admin/flatpages/flatpage/{page.pk}/change/",
        {"url": "/lab-rules/", "title": "Lab rules", "content": "<p>No food.</p>", "sites": [1]},
    )
    assert response.status_code == 302
    assert "<p>No food.</p>" in client.get("/pages/lab-rules/").content.decode()


def test_students_get_no_edit_link(client, alice):
    make_page("/lab-rules/", "Lab rules")
    assert "/admin/flatpages/" not in client.get("/pages/lab-rules/").content.decode()
