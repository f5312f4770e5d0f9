"""`robotide route` as a user runs it: a subprocess between loopback UDP ports, recording
what it routes to a .tlog, stopped by SIGTERM."""

import os
import signal
import socket
import subprocess
import sys
import time

from gateway.framing import Framer
from gateway.tlog import read_tlog
from tests.gateway.frames import attitude, command, heartbeat


def udp_socket():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.2)
    return s, s.getsockname()[1]


def free_port():
    s, port = udp_socket()
    s.close()
    return port


def test_route_forwards_between_udp_ports_records_and_stops_on_sigterm(tmp_path):
    gcs, gcs_port = udp_socket()
    vehicle, _ = udp_socket()
    router_port = free_port()
    robotide = os.path.join(os.path.dirname(sys.executable), "robotide")
    process = subprocess.Popen(
        [robotide, "route", f"udp:127.0.0.1:{router_port}", "--to", f"udp:127.0.0.1:{gcs_port}",
         "--tlog", str(tmp_path / "route.tlog")], cwd="/", stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        got, framer = [], Framer()
        deadline = time.monotonic() + 15
        while not got and time.monotonic() < deadline:  # until the router is up
            vehicle.sendto(heartbeat(1, 1), ("127.0.0.1", router_port))
            try:
                data, router_addr = gcs.recvfrom(65536)
                got = framer.feed(data)
            except TimeoutError:
                pass
        assert got and got[0][0] == heartbeat(1, 1)
        frames = [attitude(1, 1, t) for t in range(100)]
        for frame in frames:
            vehicle.sendto(frame, ("127.0.0.1", router_port))
        received = []
        while len(received) < 100:
            received += [f[0] for f in framer.feed(gcs.recvfrom(65536)[0]) if f[3] == 30]
        assert received == frames
        # and back: the GCS answers to the address the router sends from
        gcs.sendto(command(255, 190, 1, 1), router_addr)
        assert Framer().feed(vehicle.recvfrom(65536)[0])[0][0] == command(255, 190, 1, 1)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=5) == 0
        assert "Traceback" not in process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        gcs.close()
        vehicle.close()
    # Every frame it routed, both ways, is in the recording, closed cleanly on SIGTERM.
    recorded = [frame for _, frame in read_tlog(tmp_path / "route.tlog")]
    assert [f for f in recorded if f != heartbeat(1, 1)] == frames + [command(255, 190, 1, 1)]
    assert heartbeat(1, 1) in recorded


def test_route_says_which_address_is_bad():
    robotide = os.path.join(os.path.dirname(sys.executable), "robotide")
    result = subprocess.run([robotide, "route", "udp:127.0.0.1:1", "--to", "udp:nonsense"],
                            capture_output=True, text=True, timeout=15)  # fmt: skip
    assert result.returncode != 0
    assert "udp:nonsense" in result.stderr or "nonsense" in result.stderr
    assert "Traceback" not in result.stderr
