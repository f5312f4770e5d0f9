"""Where a push may go: real listeners on 127.0.0.1 and ::1 show that an address on this machine
or a private network is refused before anything connects, that ROBOTIDE_PUSH_ALLOW lets a lab's
own robotides through, and that the errors never tell what answered.

A tripwire (an audit hook on socket.connect) stops and records any connect to an address that
is not this machine's while these tests run: none may go out, even from the code before this fix.
"""

import ipaddress
import socket
import sys
import threading
import time

import pytest
from django.contrib.auth.models import User
from django.core.cache import cache
from django.test import Client

from programs.models import Program
from robotide.models import ApiToken
from tests.appliance import Appliance
from tests.waiting import DEADLINE

pytestmark = pytest.mark.django_db

# -- the tripwire ---------------------------------------------------------------------------------

_tripped: list = []
_armed = threading.Event()
_lookups: list = []  # host names looked up while _counting
_counting = threading.Event()


def _is_this_machine(host: str) -> bool:
    ip = ipaddress.ip_address(host.split("%")[0])
    ip = getattr(ip, "ipv4_mapped", None) or ip
    return ip.is_loopback or ip.is_unspecified  # 0.0.0.0 and :: connect to this machine


def _audit(event, args):
    if event == "socket.getaddrinfo" and _counting.is_set():
        _lookups.append(args[0])
    if event != "socket.connect" or not _armed.is_set():
        return
    address = args[1]
    if isinstance(address, tuple) and not _is_this_machine(address[0]):
        _tripped.append(address)
        raise ConnectionRefusedError(f"tripwire: no connect to {address[0]} in tests")


sys.addaudithook(_audit)  # hooks stay for the process: this one acts only while armed


@pytest.fixture(autouse=True)
def tripwire():
    _tripped.clear()
    _armed.set()
    yield _tripped
    _armed.clear()


@pytest.fixture(autouse=True)
def _nothing_allowed(settings):
    cache.clear()  # the hourly allowances
    settings.PUSH_ALLOW = []  # whatever the environment says
    yield
    cache.clear()


# -- listeners ------------------------------------------------------------------------------------


def has_ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
    except OSError:
        return False
    return True


needs_ipv6 = pytest.mark.skipif(not has_ipv6_loopback(), reason="no IPv6 loopback here")


class Listener:
    """A TCP listener on loopback: records each connection, reads the request, sends ``reply``
    (nothing: it just closes) and closes."""

    def __init__(self, host="127.0.0.1", reply=b""):
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family)
        self.sock.bind((host, 0))
        self.sock.listen()
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.reply, self.seen, self.requests = reply, [], []
        self.running = True
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        while self.running:
            try:
                conn, peer = self.sock.accept()
            except TimeoutError:
                continue
            with conn:
                self.seen.append(peer)
                if self.reply:
                    self.requests.append(_read_request(conn))
                    conn.sendall(self.reply)

    def close(self):
        self.running = False
        self.thread.join()
        self.sock.close()


def _read_request(conn) -> bytes:
    conn.settimeout(2)
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = conn.recv(65536)
        if not chunk:
            return data
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    length = 0
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    while len(body) < length:
        chunk = conn.recv(65536)
        if not chunk:
            break
        body += chunk
    return head + b"\r\n\r\n" + body


@pytest.fixture
def listener():
    listeners = []

    def start(host="127.0.0.1", reply=b""):
        listeners.append(Listener(host, reply))
        return listeners[-1]

    yield start
    for each in listeners:
        each.close()


# -- a user and a program to push -----------------------------------------------------------------


@pytest.fixture
def alice():
    return User.objects.create_user("alice", password="pw-alice-123")


@pytest.fixture
def program(alice):
    program = Program.objects.create(owner=alice, name="hello", language="python")
    program.save_source("print('hello')\n", alice)
    return program


@pytest.fixture
def push(alice, program):
    _, token = ApiToken.issue(alice)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def push(url, token="t", which=program):
        body = {"url": url, "token": token}
        return client.post(f"/api/programs/{which.pk}/push", body, content_type="application/json")

    return push


def refused(push, url):
    """Refused, naming the setting that would allow it; whether anything was contacted is
    what the tripwire and settle() say (no timing: a busy machine answers late, rightly)."""
    response = push(url)
    assert response.status_code == 403, response.content
    assert "ROBOTIDE_PUSH_ALLOW" in response.json()["detail"]
    return response


def settle(*listeners):
    """Who connected to the listeners before now. A connect made by the code under test was
    complete (the kernel's handshake) before its request answered, so it is in the listener's
    accept queue ahead of a probe of ours: once the probe is seen, so is anything before it."""
    probes = []
    for each in listeners:
        with socket.create_connection(each.sock.getsockname()[:2]) as probe:
            probes.append(probe.getsockname())
    deadline = time.monotonic() + DEADLINE  # a deadline for an event, not a guessed time
    while not all(probe in each.seen for each, probe in zip(listeners, probes, strict=True)):
        assert time.monotonic() < deadline, "a listener never saw the probe"
        time.sleep(0.01)
    return [peer for each in listeners for peer in each.seen if peer not in probes]


# -- addresses of this machine: refused, never contacted ------------------------------------------


def test_ipv4_loopback_is_refused_uncontacted(push, listener, tripwire):
    local = listener("127.0.0.1")
    refused(push, f"http://127.0.0.1:{local.port}")
    assert settle(local) == [] and tripwire == []


def test_another_ipv4_loopback_is_refused_uncontacted(push, listener):
    local = listener("127.0.0.1")
    refused(push, f"http://127.1.2.3:{local.port}/robotide")  # all of 127/8 is this machine
    assert settle(local) == []


@needs_ipv6
def test_ipv6_loopback_is_refused_uncontacted(push, listener, tripwire):
    local = listener("::1")
    refused(push, f"http://[::1]:{local.port}")
    assert settle(local) == [] and tripwire == []


def test_a_name_of_loopback_is_refused_uncontacted(push, listener, tripwire):
    local = listener("127.0.0.1")
    refused(push, f"http://localhost:{local.port}")
    assert settle(local) == [] and tripwire == []


def test_the_unspecified_address_is_refused_uncontacted(push, listener, tripwire):
    local = listener("127.0.0.1")  # a connect to 0.0.0.0 reaches 127.0.0.1 on Linux
    refused(push, f"http://0.0.0.0:{local.port}")
    assert settle(local) == [] and tripwire == []


@needs_ipv6
def test_ipv4_mapped_ipv6_loopback_is_refused_uncontacted(push, listener, tripwire):
    local = listener("127.0.0.1")
    refused(push, f"http://[::ffff:127.0.0.1]:{local.port}")
    assert settle(local) == [] and tripwire == []


# -- other places not to go: refused before any connect -------------------------------------------


@pytest.mark.parametrize(
    "host",
    [
        "169.254.169.254",  # the cloud's metadata service
        "10.1.2.3",
        "172.16.0.1",
        "192.168.1.20",
        "100.64.0.1",  # carrier-grade NAT: not private, not global
        "224.0.0.1",  # multicast
        "255.255.255.255",
        "[fe80::1]",
        "[fd00::1]",
        "[fec0::1]",  # site-local: deprecated, not public
        "[64:ff9b::7f00:1]",  # NAT64 of 127.0.0.1
        "[64:ff9b::a9fe:a9fe]",  # NAT64 of 169.254.169.254
        "[2002:7f00:1::1]",  # 6to4 of 127.0.0.1
        "[2002:c0a8:114::1]",  # 6to4 of 192.168.1.20
        "[ff02::1]",
    ],
)
def test_private_and_special_addresses_are_refused_before_any_connect(push, tripwire, host):
    refused(push, f"http://{host}:8000")
    assert tripwire == []


def test_the_metadata_address_is_refused_over_https_too(push, tripwire):
    refused(push, "https://169.254.169.254/latest/meta-data")
    assert tripwire == []


def test_a_refusal_does_not_say_what_is_there(push, listener):
    local = listener("127.0.0.1")
    ours = refused(push, f"http://127.0.0.1:{local.port}").json()["detail"]
    nobody = refused(push, "http://10.9.9.9:8000").json()["detail"]
    assert ours.replace(f"127.0.0.1:{local.port}", "X") == nobody.replace("10.9.9.9:8000", "X")


# -- ROBOTIDE_PUSH_ALLOW: a lab's own robotides ---------------------------------------------------


@pytest.fixture(scope="module")
def lab_robotide(tmp_path_factory):
    """A second, real robotide on 127.0.0.1, as a lab's robot on its LAN."""
    app = Appliance(tmp_path_factory.mktemp("lab")).start()
    app.dave = app.new_user("dave")
    yield app
    app.stop()


def test_an_allowed_lab_address_is_pushed_to_and_only_that(push, settings, lab_robotide):
    settings.PUSH_ALLOW = ["10.0.5.0/24", "127.0.0.1"]
    response = push(lab_robotide.url, token=lab_robotide.dave)
    assert response.status_code == 200, response.content
    assert response.json()["owner"] == "dave" and response.json()["url"] == lab_robotide.url
    settings.PUSH_ALLOW = ["10.0.5.0/24", "192.168.1.20", "127.0.0.2"]  # not 127.0.0.1
    refused(push, lab_robotide.url)


def test_the_name_is_looked_up_once_per_push(push, settings, lab_robotide, alice):
    settings.PUSH_ALLOW = ["127.0.0.0/8", "::1"]
    other = Program.objects.create(owner=alice, name="looked up once", language="python")
    url = lab_robotide.url.replace("127.0.0.1", "localhost")
    assert push(url, token=lab_robotide.dave, which=other).status_code == 200
    _lookups.clear()
    _counting.set()
    try:
        # The name is taken there: it posts twice ("... (2)"), to the address looked up once.
        again = push(url, token=lab_robotide.dave, which=other)
    finally:
        _counting.clear()
    assert again.status_code == 200 and again.json()["name"] == "looked up once (2)"
    assert _lookups.count("localhost") == 1, _lookups


# -- what answers is not told ---------------------------------------------------------------------

NOT_A_ROBOTIDE = "{} is not a robotide, or not its own address (redirects are not followed)."
NOT_REACHABLE = "{} is not reachable."


@pytest.fixture
def lab(settings):
    settings.PUSH_ALLOW = ["127.0.0.1", "::1"]


def not_a_robotide(push, local, secret: bytes, host="127.0.0.1"):
    url = f"http://{host}:{local.port}"
    response = push(url, token="rt_secret")
    detail = response.json()["detail"]
    assert response.status_code == 502
    assert detail == NOT_A_ROBOTIDE.format(url)
    assert secret.decode() not in detail
    [request] = local.requests  # to the address checked, under the name given
    assert b"Bearer rt_secret" in request and f"Host: {host}:{local.port}".encode() in request


def test_redis_is_not_a_robotide(push, listener, lab):
    not_a_robotide(push, listener(reply=b"+PONG\r\n"), b"PONG")


def test_an_http_401_is_not_a_robotide(push, listener, lab):
    reply = (
        b'HTTP/1.1 401 Unauthorized\r\nWWW-Authenticate: Basic realm="pg-admin"\r\n'
        b"Content-Type: text/html\r\nContent-Length: 17\r\nConnection: close\r\n\r\n"
        b"<h1>pg-admin</h1>"
    )
    not_a_robotide(push, listener(reply=reply), b"pg-admin", host="localhost")


def test_a_json_answer_of_another_shape_is_not_a_robotide(push, listener, lab):
    body = b'{"Code": "Success", "AccessKeyId": "ASIA-SECRET"}'
    reply = (
        b"HTTP/1.1 201 Created\r\nContent-Type: application/json\r\n"
        b"Content-Length: %d\r\nConnection: close\r\n\r\n%s" % (len(body), body)
    )
    not_a_robotide(push, listener(reply=reply), b"ASIA-SECRET")


def test_a_redirect_is_not_followed_nor_told(push, listener, lab, tripwire):
    reply = (
        b"HTTP/1.1 307 Temporary Redirect\r\nLocation: http://169.254.169.254/latest\r\n"
        b"Content-Length: 0\r\nConnection: close\r\n\r\n"
    )
    not_a_robotide(push, listener(reply=reply), b"169.254")
    assert tripwire == []


def test_a_listener_that_closes_is_only_not_reachable(push, listener, lab):
    local = listener()  # accepts and closes without a word
    url = f"http://127.0.0.1:{local.port}"
    response = push(url)
    assert response.status_code == 502
    assert response.json()["detail"] == NOT_REACHABLE.format(url)
    assert len(local.seen) == 1
