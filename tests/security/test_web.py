"""Web security of a live appliance: the Content Security Policy (in headers and in a real
browser), CSRF on every form, login throttling, secure cookies and HSTS over HTTPS, request size
limits, and websockets only from the appliance's own pages.
"""

import re
import time
from html.parser import HTMLParser

import httpx
import pytest
import websockets
from playwright.sync_api import Page, expect
from websockets.sync.client import connect

from tests.appliance import ADMIN_PASSWORD, Appliance, cookie_header

LOCK_SECONDS = 3
ADDRESS_FAILURES = 30
USER_PASSWORD = "user-pass-1234"
THROTTLED = re.compile(r"Too many failed sign-ins; try again in \d+ seconds?\.")

SHOW_AND_TELL = """\
import time

import robot

bot = robot.Robot()
print("<script>document.title = 'pwned'</script><img src=x onerror=alert(1)>", flush=True)
bot.show("drawing", '<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">'
         '<circle cx="20" cy="20" r="15" style="fill: tomato"/></svg>')
bot.show("<b>name</b>", "<i>value</i>")
for i in range(600):
    print("tick", i, flush=True)
    time.sleep(0.1)
"""


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    """This module's own appliance, with a lock short enough to wait out."""
    env = {
        "ROBOTIDE_LOGIN_LOCK_SECONDS": str(LOCK_SECONDS),
        "ROBOTIDE_LOGIN_WINDOW_SECONDS": "120",
        "ROBOTIDE_LOGIN_ADDRESS_FAILURES": str(ADDRESS_FAILURES),
    }
    app = Appliance(tmp_path_factory.mktemp("security"), extra_env=env).start()
    yield app
    app.stop()


@pytest.fixture(scope="module")
def client(appliance) -> httpx.Client:
    client = appliance.session()
    client.follow_redirects = False
    yield client
    client.close()


@pytest.fixture(scope="module")
def program(appliance) -> dict:
    return appliance.create_program("Show and tell", SHOW_AND_TELL)


@pytest.fixture
def run(appliance, program):
    """A run of `program`, going for a minute unless stopped."""
    run = appliance.run_program(program["id"])
    appliance.wait_run(run["id"], states=("running",))
    yield run
    appliance.api("POST", f"/api/runs/{run['id']}/stop")
    appliance.wait_run(run["id"])


def pages(program: dict, run: dict) -> list[str]:
    """A page of every kind, the admin's and the API's included."""
    p, r = program["id"], run["id"]
    return [
        "/programs/",
        f"/programs/{p}/",
        f"/programs/{p}/revisions/",
        f"/programs/{p}/revisions/1/",
        f"/programs/{p}/delete",
        "/runs/",
        f"/runs/{r}/",
        f"/runs/{r}/log",
        "/robots/",
        "/robots/sim/",
        "/accounts/password/",
        "/admin/",
        "/admin/programs/program/",
        f"/admin/programs/program/{p}/change/",
        "/admin/auth/user/add/",
        "/api/docs",
        "/api/openapi.json",
        "/api/programs",
    ]


def sign_in(appliance, username, password, path="/accounts/login/") -> httpx.Response:
    with httpx.Client(base_url=appliance.url, follow_redirects=True, timeout=10) as client:
        page = client.get(path)
        csrf = re.search(r'name="csrfmiddlewaretoken" value="([^"]+)"', page.text).group(1)
        data = {"username": username, "password": password, "csrfmiddlewaretoken": csrf}
        return client.post(path, data=data)


def signed_in(response: httpx.Response) -> bool:
    return "Sign out" in response.text or "Site administration" in response.text


def wait_out_the_lock() -> None:
    time.sleep(LOCK_SECONDS + 0.5)


# -- headers --------------------------------------------------------------------------------------


def policy(response: httpx.Response) -> dict[str, list[str]]:
    header = response.headers["content-security-policy"]
    return {d.split()[0]: d.split()[1:] for d in header.split(";") if d.strip()}


def assert_strict_headers(response: httpx.Response, appliance) -> None:
    csp = policy(response)
    assert csp["default-src"] == ["'self'"]
    assert csp["script-src"] == ["'self'"]  # no 'unsafe-inline', no 'unsafe-eval'
    assert csp["style-src"] == ["'self'"]
    assert sorted(csp["img-src"]) == ["'self'", "data:"]
    assert csp["connect-src"] == ["'self'", appliance.url.replace("http://", "ws://")]
    assert csp["frame-ancestors"] == ["'none'"]
    assert csp["object-src"] == ["'none'"]
    assert csp["base-uri"] == ["'self'"]
    assert csp["form-action"] == ["'self'"]
    assert "unsafe" not in response.headers["content-security-policy"]
    assert response.headers["x-frame-options"] == "DENY"
    assert response.headers["x-content-type-options"] == "nosniff"
    assert response.headers["referrer-policy"] == "same-origin"


def test_every_page_has_a_strict_policy(appliance, client, program, run):
    anonymous = httpx.get(f"{appliance.url}/accounts/login/")
    assert anonymous.status_code == 200
    assert_strict_headers(anonymous, appliance)
    for path in pages(program, run):
        response = client.get(path)
        assert response.status_code == 200, path
        assert_strict_headers(response, appliance)
    missing = client.get("/no/such/page")
    assert missing.status_code == 404
    assert_strict_headers(missing, appliance)


def test_the_session_cookie_is_http_only_lax_and_lasts_12_hours(appliance):
    response = sign_in(appliance, "admin", ADMIN_PASSWORD)
    cookie = next(h for h in response.history[0].headers.get_list("set-cookie")
                  if h.startswith("sessionid="))  # fmt: skip
    assert "HttpOnly" in cookie and "SameSite=Lax" in cookie and "Max-Age=43200" in cookie
    assert "Secure" not in cookie  # plain HTTP here: see test_https_cookies_and_hsts


# -- the policy in a real browser ----------------------------------------------------------------

REPORT_VIOLATIONS = """
document.addEventListener("securitypolicyviolation", (e) => {
  console.error(`CSP violation: ${e.violatedDirective} blocked ${e.blockedURI || "inline"}`);
});
"""


def test_no_page_breaks_the_policy_in_a_browser(appliance, new_page, program, run):
    page: Page = new_page()
    violations = []
    page.add_init_script(REPORT_VIOLATIONS)
    page.on(
        "console",
        lambda m: (
            ("Content Security Policy" in m.text or "CSP violation" in m.text)
            and violations.append(f"{page.url}: {m.text}")
        ),
    )

    page.goto("/accounts/login/")
    page.get_by_label("User name").fill("admin")
    page.get_by_label("Password").fill(ADMIN_PASSWORD)
    page.get_by_role("button", name="Sign in").click()
    expect(page.get_by_role("button", name="Sign out")).to_be_visible()

    page.goto(f"/programs/{program['id']}/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    expect(page.locator(".CodeMirror")).to_contain_text("bot.show")

    # Live output over the websocket; the program's HTML is shown as text, never run.
    page.goto(f"/runs/{run['id']}/")
    ticks = re.findall(r"tick (\d+)", page.locator("#log-lines").inner_text())
    start = int(ticks[-1]) if ticks else 0
    expect(page.locator("#log-lines")).to_contain_text(f"tick {start + 10}")
    expect(page.locator("#log-lines")).to_contain_text("<script>document.title = 'pwned'</script>")
    assert "pwned" not in page.title()

    # Readings and a program's SVG drawing (a data: image) over the robot's websocket.
    page.goto("/robots/sim/")
    expect(page.locator("#sensors")).to_contain_text("heading")
    drawing = page.locator("#shows img[alt='drawing']")
    expect(drawing).to_have_attribute("src", re.compile(r"^data:image/svg\+xml"))
    expect(page.locator("#shows")).to_contain_text("<i>value</i>")
    assert page.evaluate("document.querySelector('#shows img').naturalWidth") > 0

    for path in pages(program, run):
        if path.endswith("/log") or path.startswith("/api/"):
            continue  # a download, JSON
        page.goto(path)
        expect(page.locator("body")).not_to_be_empty()
    page.goto("/api/docs")
    expect(page.locator(".swagger-ui .info")).to_contain_text("robotide")

    # The htmx stop button: a POST with the CSRF header from <body hx-headers>.
    page.goto(f"/runs/{run['id']}/")
    page.get_by_role("button", name="■ Stop").click()
    expect(page.locator("#run-status")).to_contain_text("stopped")

    assert violations == []


# -- CSRF -----------------------------------------------------------------------------------------


class Forms(HTMLParser):
    """The forms of a page: method, action and the names of their inputs."""

    def __init__(self, html: str):
        super().__init__()
        self.forms: list[dict] = []
        self.body: dict = {}
        self.open = False
        self.feed(html)

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "body":
            self.body = attrs
        elif tag == "form":
            method = (attrs.get("method") or "get").lower()
            self.forms.append({"method": method, "action": attrs.get("action"), "inputs": set()})
            self.open = True
        elif tag == "input" and self.open:
            self.forms[-1]["inputs"].add(attrs.get("name"))

    def handle_endtag(self, tag):
        if tag == "form":
            self.open = False


def test_every_post_form_carries_a_csrf_token_and_is_refused_without(
    appliance, client, program, run
):
    checked = 0
    for path in ["/accounts/login/", *pages(program, run)]:
        response = client.get(path)
        if not response.headers["content-type"].startswith("text/html"):
            continue
        parsed = Forms(response.text)
        if "htmx.min.js" in response.text:
            # htmx requests send the token as a header (the browser test presses an htmx button).
            headers = parsed.body["hx-headers"]
            assert re.fullmatch(r'\{"X-CSRFToken": "\w{64}"\}', headers), path
        for form in parsed.forms:
            if form["method"] != "post":
                continue
            assert "csrfmiddlewaretoken" in form["inputs"], f"{path}: {form}"
            action = form["action"] or path
            refused = client.post(action, data={"next": "/"})
            assert refused.status_code == 403, f"{path}: {action} without a token"
            checked += 1
    assert checked >= 15
    assert appliance.api("GET", f"/api/programs/{program['id']}").status_code == 200
    assert appliance.api("GET", f"/api/runs/{run['id']}").json()["state"] == "running"


def test_the_api_with_a_session_requires_the_csrf_token(appliance, client):
    body = {"name": "by session", "language": "python", "source": "print(1)\n"}
    assert client.post("/api/programs", json=body).status_code == 403
    assert client.delete("/api/programs/1").status_code == 403
    headers = {"X-CSRFToken": client.cookies["csrftoken"]}
    assert client.post("/api/programs", json=body, headers=headers).status_code == 201
    assert client.get("/api/programs").status_code == 200  # reading needs no token


def test_websockets_only_from_the_appliances_own_pages(appliance, client, run):
    cookie = cookie_header(client)
    url = appliance.url.replace("http://", "ws://") + f"/ws/runs/{run['id']}/"

    def first_message(origin: str) -> str:
        # The sync client: the browser fixture keeps an event loop running in this thread.
        headers = {"Cookie": cookie, "Origin": origin}
        with connect(url, additional_headers=headers, open_timeout=5) as ws:
            return ws.recv(timeout=5)

    assert first_message(appliance.url).startswith("<")  # an HTML fragment for htmx
    for origin in ("http://evil.example", appliance.url.rsplit(":", 1)[0] + ":1"):
        with pytest.raises(websockets.InvalidStatus) as refused:
            first_message(origin)
        assert refused.value.response.status_code == 403


# -- login throttling -----------------------------------------------------------------------------


def test_repeated_failures_lock_the_name_from_this_address_for_a_while(appliance):
    appliance.new_user("tina", USER_PASSWORD)
    appliance.new_user("tom", USER_PASSWORD)
    for _ in range(4):
        response = sign_in(appliance, "tina", "wrong password")
        assert "Please enter a correct username and password" in response.text
    assert THROTTLED.search(sign_in(appliance, "tina", "wrong again").text)
    locked = sign_in(appliance, "tina", USER_PASSWORD)  # the right password waits too
    assert THROTTLED.search(locked.text) and not signed_in(locked)
    assert signed_in(sign_in(appliance, "tom", USER_PASSWORD))  # others from here are not locked
    wait_out_the_lock()
    assert signed_in(sign_in(appliance, "tina", USER_PASSWORD))


def test_a_right_password_forgives_earlier_failures(appliance):
    appliance.new_user("ursula", USER_PASSWORD)
    for _ in range(4):
        assert not signed_in(sign_in(appliance, "ursula", "wrong password"))
    assert signed_in(sign_in(appliance, "ursula", USER_PASSWORD))
    for _ in range(4):
        response = sign_in(appliance, "ursula", "wrong password")
        assert not THROTTLED.search(response.text)


def test_the_admin_sign_in_is_throttled_too(appliance):
    for _ in range(5):
        response = sign_in(appliance, "admin", "wrong password", path="/admin/login/")
    assert THROTTLED.search(response.text)
    locked = sign_in(appliance, "admin", ADMIN_PASSWORD, path="/admin/login/")
    assert THROTTLED.search(locked.text) and not signed_in(locked)
    wait_out_the_lock()
    assert signed_in(sign_in(appliance, "admin", ADMIN_PASSWORD, path="/admin/login/"))


def test_many_failures_from_one_address_lock_the_address(appliance):
    appliance.new_user("victor", USER_PASSWORD)
    for attempt in range(ADDRESS_FAILURES):
        # Never 5 for one name: only the address's count can lock.
        response = sign_in(appliance, f"guess{attempt // 4}", "wrong password")
        if THROTTLED.search(response.text):
            break
    else:
        pytest.fail(f"{ADDRESS_FAILURES} failures from one address did not lock it")
    locked = sign_in(appliance, "victor", USER_PASSWORD)
    assert THROTTLED.search(locked.text) and not signed_in(locked)
    wait_out_the_lock()
    assert signed_in(sign_in(appliance, "victor", USER_PASSWORD))


# -- request size ---------------------------------------------------------------------------------


def test_an_over_size_upload_is_refused_cleanly(appliance, client):
    csrf = {"csrfmiddlewaretoken": client.cookies["csrftoken"]}
    huge = client.post("/programs/upload", data=csrf,
                       files={"file": ("huge.py", b"#" * 3_000_000)})  # fmt: skip
    assert huge.status_code == 413
    assert "Request too large: at most 2048 KB (a program may be 512 KB)" in huge.text
    large = client.post("/programs/upload", data=csrf,
                        files={"file": ("large.py", b"#" * 600_000)})  # fmt: skip
    assert large.status_code == 400 and "Programs are limited to 512 KB." in large.text
    api = appliance.api("POST", "/api/programs", {"name": "x", "language": "python",
                                                  "source": "#" * 3_000_000})  # fmt: skip
    assert api.status_code == 413 and "Request too large" in api.json()["detail"]
    fields = client.post("/programs/new", data={**csrf, **{f"f{i}": "" for i in range(1000)}})
    assert fields.status_code == 400 and fields.text == "Request refused: more than 400 fields."
    files = [("file", (f"{i}.py", b"print()\n")) for i in range(20)]
    many = client.post("/programs/upload", data=csrf, files=files)
    assert many.status_code == 400 and many.text == "Request refused: more than 10 files."
    assert appliance.api("GET", "/api/programs").status_code == 200  # still serving


# -- HTTPS ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def https_appliance(tmp_path_factory):
    """Behind a TLS-terminating proxy, which says so in X-Forwarded-Proto."""
    env = {"ROBOTIDE_HTTPS": "true", "ROBOTIDE_BEHIND_PROXY": "true", "ROBOTIDE_SESSION_HOURS": "2"}
    app = Appliance(tmp_path_factory.mktemp("https"), extra_env=env).start()
    yield app
    app.stop()


def test_https_cookies_and_hsts(https_appliance):
    app = https_appliance
    proxied = {"X-Forwarded-Proto": "https"}
    page = httpx.get(f"{app.url}/accounts/login/", headers=proxied)
    assert page.headers["strict-transport-security"] == "max-age=31536000; includeSubDomains"
    assert policy(page)["connect-src"] == ["'self'", app.url.replace("http://", "wss://")]
    csrf_cookie = next(h for h in page.headers.get_list("set-cookie") if h.startswith("csrftoken="))
    assert "; Secure" in csrf_cookie
    # httpx keeps Secure cookies from http:// URLs: send it as the browser would over HTTPS.
    cookie = csrf_cookie.split(";")[0]
    csrf = re.search(r'name="csrfmiddlewaretoken" value="([^"]+)"', page.text).group(1)
    signed = httpx.post(
        f"{app.url}/accounts/login/",
        data={"username": "admin", "password": ADMIN_PASSWORD, "csrfmiddlewaretoken": csrf},
        headers={**proxied, "Cookie": cookie, "Origin": app.url.replace("http://", "https://")},
    )
    assert signed.status_code == 302
    session = next(h for h in signed.headers.get_list("set-cookie") if h.startswith("sessionid="))
    for flag in ("; Secure", "; HttpOnly", "; SameSite=Lax", "; Max-Age=7200"):
        assert flag in session
    # Without the proxy's word the request is plain HTTP: no HSTS.
    plain = httpx.get(f"{app.url}/accounts/login/")
    assert "strict-transport-security" not in plain.headers
