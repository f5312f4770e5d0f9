"""What the network tests share: a DNS query a run's program makes, and a UDP service on the
host's 127.0.0.1 that answers in a thread of its own."""

import contextlib
import socket
import threading

# A program's lookup through the resolver its /etc/resolv.conf names: a name under .invalid
# (RFC 6761), which a resolver answers (NXDOMAIN) without asking anyone outside. Prints
# "SERVERS [...]", then "DNS answered 20817" (the query's id) or "DNS unanswered ERROR".
DNS_PROBE = r"""
import socket, struct
servers = [l.split()[1] for l in open("/etc/resolv.conf") if l.startswith("nameserver")]
print("SERVERS", servers)
name = b"".join(bytes([len(p)]) + p for p in b"robotide-probe.invalid".split(b"."))
query = struct.pack(">6H", 0x5151, 0x0100, 1, 0, 0, 0) + name + bytes(1) + struct.pack(">2H", 1, 1)
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.settimeout(5)
try:
    s.sendto(query, (servers[0], 53))
    print("DNS answered", struct.unpack(">H", s.recv(512)[:2])[0])
except (OSError, IndexError) as e:
    print("DNS unanswered", type(e).__name__)
"""
DNS_ANSWERED = "DNS answered 20817"


@contextlib.contextmanager
def udp_service(prefix: bytes = b""):
    """A UDP service on the host's 127.0.0.1 answering each datagram with `prefix` + it;
    yields its socket's address."""
    service = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    service.bind(("127.0.0.1", 0))
    service.settimeout(0.2)
    stop = threading.Event()

    def answer():
        while not stop.is_set():
            try:
                data, peer = service.recvfrom(100)
                service.sendto(prefix + data, peer)
            except OSError:
                pass

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    try:
        yield service.getsockname()
    finally:
        stop.set()
        thread.join(5)
        service.close()
