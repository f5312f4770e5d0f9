"""A run's network is its own: whatever its robot's setting, nothing of the host's loopback,
its own addresses or its private ranges is reachable; only what the robot gives programs.

Each probe is a student's program on a real appliance, trying the host's services: the
PostgreSQL and Redis this machine runs, the appliance's own web server, a TCP and a UDP
listener and an abstract Unix socket the test opens on the host.
"""

import ipaddress
import json
import os
import socket
import threading
import time

import pytest

from runbox.netspec import host_addresses
from tests.appliance import Appliance, wait_for
from tests.net_probes import DNS_ANSWERED, DNS_PROBE, udp_service
from tests.security.test_program_attacks import attack

PROBE = """
import json, os, socket
report = {}
def tcp(host, port):
    try:
        socket.create_connection((host, port), timeout=2).close()
        return "connected"
    except OSError as e:
        return type(e).__name__
def udp(host, port):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(1.5)
    try:
        s.sendto(b"ping", (host, port))
        return "answered " + s.recv(100).decode()
    except OSError as e:
        return type(e).__name__
for name, (host, port) in TARGETS.items():
    report[name] = tcp(host, port)
report["udp"] = udp("127.0.0.1", UDP_PORT)
try:
    a = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    a.connect(ABSTRACT)
    report["abstract"] = "connected"
except OSError as e:
    report["abstract"] = type(e).__name__
report["proc_net_tcp"] = open("/proc/net/tcp").read().splitlines()[1:]
report["api"] = tcp("127.0.0.1", int(os.environ["ROBOT_API_TCP"].rsplit(":", 1)[1]))
report["routes"] = open("/proc/net/route").read().splitlines()[1:]
print("REPORT", json.dumps(report))
"""


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("network")).start()
    for name, network in [("lab", "loopback"), ("open", "full")]:
        body = {"name": name, "url": "sim://", "settings": {"network": network}}
        assert app.api("POST", "/api/robots", body).status_code == 201
        wait_for(lambda n=name: app.api("GET", f"/api/robots/{n}/sensors").status_code == 200)
    app.bystander = app.new_user("bystander")
    yield app
    app.stop()


@pytest.fixture(scope="module")
def host_listeners():
    """A TCP listener, a UDP echo and an abstract socket on the host, each answering."""
    tcp = socket.create_server(("127.0.0.1", 0))
    abstract = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    name = f"\0robotide-test-{os.getpid()}"
    abstract.bind(name)
    abstract.listen()
    with udp_service(b"pong") as udp:
        yield {"tcp": tcp.getsockname()[1], "udp": udp[1], "abstract": name}
    for sock in (tcp, abstract):
        sock.close()


def probe(app, robot, listeners, more=()):
    targets = {
        "postgresql": ("127.0.0.1", 5432),
        "redis": ("127.0.0.1", 6379),
        "web server": ("127.0.0.1", app.port),
        "tcp listener": ("127.0.0.1", listeners["tcp"]),
        "localhost name": ("localhost", 5432),
        **{f"host address {a}": (a, 5432) for a in host_addresses() if a != "127.0.0.1"},
        **dict(more),
    }
    source = (
        f"TARGETS = {targets!r}\nUDP_PORT = {listeners['udp']}\n"
        f"ABSTRACT = {listeners['abstract']!r}\n{PROBE}"
    )
    run, log = attack(app, source, robot=robot)
    assert run["state"] == "finished", log
    return json.loads(log.split("REPORT ", 1)[1].splitlines()[0]), targets


def host_services_are_up(listeners):
    for port in (5432, 6379, listeners["tcp"]):
        socket.create_connection(("127.0.0.1", port), timeout=2).close()


@pytest.mark.parametrize("robot", ["lab", "open"])
def test_a_run_reaches_nothing_of_the_host(app, host_listeners, robot):
    host_services_are_up(host_listeners)  # they answer the host: the probe's refusals count
    report, targets = probe(app, robot, host_listeners)
    for name in targets:
        assert report[name] != "connected", (name, report)
    assert not report["udp"].startswith("answered"), report
    assert report["abstract"] != "connected", report
    assert report["api"] == "connected", report  # what its robot gives programs is there


@pytest.mark.parametrize("robot", ["lab", "open"])
def test_proc_net_shows_the_runs_own_namespace_only(app, host_listeners, robot):
    report, _ = probe(app, robot, host_listeners)
    # The Robot API's listener and the probe's own connection to it, nothing else.
    api = f"{7010:04X}"
    for line in report["proc_net_tcp"]:
        local, remote = line.split()[1:3]
        assert api in (local.split(":")[1], remote.split(":")[1]), report["proc_net_tcp"]


def test_full_network_has_a_way_out_but_not_to_private_ranges(app, host_listeners):
    """No traffic may leave this machine in a test: the private ranges are checked in the
    run's routing table (refusing routes), not tried; the host's loopback behind the NAT's
    gateway and the host's own addresses are tried."""
    report, _ = probe(
        app, "open", host_listeners, more={"NAT gateway (the host's loopback)": ("10.0.2.2", 5432)}
    )
    assert report["NAT gateway (the host's loopback)"] != "connected", report
    assert default_route(report) == ["tap0"], report["routes"]
    refused = refused_routes(report)
    for network in ("10.0.0.0/8", "172.16.0.0/12", "192.168.0.0/16", "169.254.0.0/16",
                    "127.0.0.0/8", *(f"{a}/32" for a in host_addresses())):  # fmt: skip
        assert ipaddress.ip_network(network) in refused, (network, report["routes"])
    lab, _ = probe(app, "lab", host_listeners)
    assert default_route(lab) == [], lab["routes"]


def refused_routes(report) -> set:
    """The networks /proc/net/route lists with RTF_REJECT (prohibit routes)."""
    found = set()
    for row in (line.split() for line in report["routes"]):
        if int(row[3], 16) & 0x0200:
            address = ipaddress.IPv4Address(bytes.fromhex(row[1])[::-1])
            mask = bin(int.from_bytes(bytes.fromhex(row[7])[::-1], "big")).count("1")
            found.add(ipaddress.ip_network(f"{address}/{mask}"))
    return found


def default_route(report) -> list[str]:
    """The interfaces of the routes to 0.0.0.0/0 in the run's /proc/net/route."""
    rows = [line.split() for line in report["routes"]]
    return [row[0] for row in rows if row[1] == "00000000" and row[7] == "00000000"]


def test_the_runs_of_one_robot_do_not_share_a_namespace(app):
    waiting = "import socket, time\ns = socket.create_server(('127.0.0.1', 6000))\ntime.sleep(20)\n"
    first = app.run_program(app.create_program("holder", waiting)["id"], robot="lab")["id"]
    wait_for(lambda: app.api("GET", f"/api/runs/{first}").json()["state"] == "running")
    time.sleep(0.5)
    source = (
        "import socket\ntry:\n    socket.create_connection(('127.0.0.1', 6000), timeout=2)\n"
        "    print('REACHED')\nexcept OSError as e:\n    print('REFUSED', type(e).__name__)\n"
        "s = socket.create_server(('127.0.0.1', 6000))\nprint('BOUND too')\n"
    )
    run, log = attack(app, source, robot="lab")
    app.api("POST", f"/api/runs/{first}/stop")
    assert "REFUSED" in log and "BOUND too" in log and "REACHED" not in log, log


def test_a_port_the_robot_names_is_relayed_and_no_other(app, host_listeners):
    """A host service the robot's settings list in loopback_ports (say, a ROS bridge) is at
    the same port on the run's 127.0.0.1; the TCP listener next to it is not."""
    echo = socket.create_server(("127.0.0.1", 0))
    port = echo.getsockname()[1]

    def answer():
        connection, _ = echo.accept()
        with connection:
            connection.sendall(b"bridge " + connection.recv(100))

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    body = {"name": "bridged", "url": "sim://",
            "settings": {"network": "loopback", "loopback_ports": [f"tcp:{port}"]}}  # fmt: skip
    assert app.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: app.api("GET", "/api/robots/bridged/sensors").status_code == 200)
    source = f"""
import socket
s = socket.create_connection(("127.0.0.1", {port}), timeout=3)
s.sendall(b"hello")
print("GOT", s.recv(100))
try:
    socket.create_connection(("127.0.0.1", {host_listeners["tcp"]}), timeout=2)
    print("REACHED the other")
except OSError as e:
    print("other refused", type(e).__name__)
"""
    run, log = attack(app, source, robot="bridged")
    thread.join(5)
    echo.close()
    assert "GOT b'bridge hello'" in log and "other refused" in log, log


def test_a_full_run_looks_names_up_through_its_nat(app):
    """The host's resolver is often on a private range (a LAN's router, a cloud's resolver,
    systemd-resolved's 127.0.0.53), which a `full` run may not reach: its names are looked up
    through the NAT's own DNS forwarder instead. The probe asks for a name under .invalid
    (RFC 6761), which the host's resolver answers (NXDOMAIN) without asking anyone outside."""
    run, log = attack(app, DNS_PROBE, robot="open")
    assert "SERVERS ['10.0.2.3']" in log and DNS_ANSWERED in log, log


def test_an_allowed_lan_leaves_the_host_on_it_shut(app):
    """A teacher opens the lab's LAN (the range of this machine's own address) to a `full`
    robot: a server listening on all of the host's addresses stays out of reach."""
    own = [a for a in host_addresses() if not a.startswith("127.")]
    assert own, "this machine has no address but its loopback: nothing to probe"
    lan = str(ipaddress.ip_network(f"{own[0]}/24", strict=False))
    body = {"name": "lan", "url": "sim://",
            "settings": {"network": "full", "allow_networks": [lan]}}  # fmt: skip
    assert app.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: app.api("GET", "/api/robots/lan/sensors").status_code == 200)
    everywhere = socket.create_server(("0.0.0.0", 0))
    port = everywhere.getsockname()[1]
    socket.create_connection((own[0], port), timeout=2).close()  # it answers the host
    source = f"""
import socket
try:
    socket.create_connection(({own[0]!r}, {port}), timeout=3)
    print("REACHED the host")
except OSError as e:
    print("host refused", type(e).__name__)
"""
    try:
        run, log = attack(app, source, robot="lan")
    finally:
        everywhere.close()
    assert "host refused" in log and "REACHED" not in log, log


def test_a_udp_port_the_robot_names_is_relayed_to_each_socket_of_the_run(app, host_listeners):
    """A UDP service of the host (a camera's video stream, a telemetry feed) listed in
    loopback_ports: each socket of the run gets the answers to what it sent, and the host's
    other UDP listener stays out of reach."""
    with udp_service(b"video ") as (_, port):
        run, log = relayed_udp(app, port, host_listeners["udp"])
    assert "GOT b'video one'" in log and "GOT b'video two'" in log, log
    assert "other unanswered" in log and "REACHED" not in log, log


def relayed_udp(app, port: int, other: int):
    """A run on a new robot that relays `port`: two sockets to it, one to `other`."""
    body = {"name": "video", "url": "sim://",
            "settings": {"network": "loopback", "loopback_ports": [f"udp:{port}"]}}  # fmt: skip
    assert app.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: app.api("GET", "/api/robots/video/sensors").status_code == 200)
    source = f"""
import socket
for name in (b"one", b"two"):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(3)
    s.sendto(name, ("127.0.0.1", {port}))
    print("GOT", s.recv(100))
other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
other.settimeout(1.5)
try:
    other.sendto(b"ping", ("127.0.0.1", {other}))
    print("REACHED the other", other.recv(100))
except OSError as e:
    print("other unanswered", type(e).__name__)
"""
    return attack(app, source, robot="video")


def test_the_nat_of_a_full_run_holds_no_power_over_the_host(app):
    """slirp4netns parses every packet a student's program sends, with libslirp: as the
    agent's child it would do so as root. It runs sandboxed (its own mount namespace, every
    capability dropped but binding low ports) and under its seccomp filter."""
    program = app.create_program("waits", "import time\nprint('up', flush=True)\ntime.sleep(4)\n")
    run_id = app.run_program(program["id"], robot="open")["id"]
    wait_for(lambda: app.api("GET", f"/api/runs/{run_id}").json()["state"] == "running")
    nats = wait_for(lambda: nat_processes_of(app.server.pid), what="the run's slirp4netns")
    checked = 0
    for pid in nats:  # the run's, and the next run's box made ahead
        try:
            text = open(f"/proc/{pid}/status").read()
            namespace = os.readlink(f"/proc/{pid}/ns/mnt")
        except FileNotFoundError:  # a box made ahead and discarded meanwhile
            continue
        status = dict(line.split(":\t", 1) for line in text.splitlines())
        assert int(status["CapEff"], 16) & ~(1 << 10) == 0, status["CapEff"]  # NET_BIND_SERVICE
        assert status["Seccomp"].strip() == "2", status["Seccomp"]
        assert namespace != os.readlink("/proc/self/ns/mnt")
        checked += 1
    assert checked
    app.api("POST", f"/api/runs/{run_id}/stop")


def nat_processes_of(server: int) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = open(f"/proc/{entry}/stat").read()
            except OSError:
                continue
            name, ppid = stat.split("(", 1)[1].split(")")[0], int(stat.rsplit(")", 1)[1].split()[1])
            if name == "slirp4netns" and ppid == server:
                found.append(int(entry))
    return found
