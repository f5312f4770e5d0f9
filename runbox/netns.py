"""Sockets made inside a run's network namespace, from a thread of the agent's own.

setns(2) moves only the calling thread: one worker thread enters the run's namespace, brings
binds what the run may reach on 127.0.0.1 and comes back. The sockets stay
in the run's namespace for good and are served by the agent's event loop like any other, so
nothing of the host's loopback is reachable from inside, and no relay process runs in there.
Entering a namespace needs CAP_SYS_ADMIN where the agent lives: root (see runbox.box for the
rootless way).
"""

import ctypes
import os
import socket
import subprocess
from concurrent.futures import ThreadPoolExecutor

CLONE_NEWNET = 0x40000000
_libc = ctypes.CDLL(None, use_errno=True)
# One thread does all the entering: a thread that failed to come back is never reused by
# anything else of the agent's.
_thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="netns")


def in_namespace(pid: int, work):
    """Run `work()` inside the network namespace of process `pid`; returns what it returns."""
    return _thread.submit(_entered, pid, work)


def _entered(pid: int, work):
    home = os.open("/proc/thread-self/ns/net", os.O_RDONLY | os.O_CLOEXEC)
    target = os.open(f"/proc/{pid}/ns/net", os.O_RDONLY | os.O_CLOEXEC)
    try:
        _setns(target)
        try:
            return work()
        finally:
            _setns(home)
    finally:
        os.close(target)
        os.close(home)


def _setns(fd: int) -> None:
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"setns: {os.strerror(err)}")


def bind_loopback(services: list[str]) -> list[socket.socket]:
    """ "tcp:PORT" / "udp:PORT" -> sockets bound to 127.0.0.1 (TCP ones listening)."""
    made = []
    try:
        for service in services:
            proto, port = service.split(":")
            kind = socket.SOCK_STREAM if proto == "tcp" else socket.SOCK_DGRAM
            sock = socket.socket(socket.AF_INET, kind)
            made.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(("0.0.0.0", int(port)))
            if kind == socket.SOCK_STREAM:
                sock.listen(64)
            sock.setblocking(False)
    except BaseException:
        for sock in made:
            sock.close()
        raise
    return made


# slirp4netns's default network: the run is 10.0.2.100, the NAT's gateway .2, its DNS .3.
NAT_ADDRESS, NAT_GATEWAY, NAT_DNS = "10.0.2.100/24", "10.0.2.2", "10.0.2.3"
# A `full` run's resolv.conf: the NAT's DNS forwarder, which asks the host's resolver for it
# (that resolver is often on a range the run may not reach: a router, 127.0.0.53).
NAT_RESOLV_CONF = f"# robotide: the NAT forwards to the host's resolver\nnameserver {NAT_DNS}\n"


def configure_nat(ip: str, refused: list[str], enter: list[str] = ()) -> None:
    """In the current namespace (or the one `enter` runs `ip` in): slirp4netns's tap0 up
    as the way out, and routes that refuse the given ranges (EACCES on connect)."""
    batch = (
        f"link set tap0 mtu 65520 up\naddr add {NAT_ADDRESS} dev tap0\n"
        f"route add default via {NAT_GATEWAY} dev tap0\n"
    ) + "".join(f"route add prohibit {net}\n" for net in refused)
    done = subprocess.run(
        [*enter, ip, "-batch", "-"], input=batch, text=True, capture_output=True, timeout=10
    )
    if done.returncode != 0:
        raise OSError(f"ip route: {done.stderr.strip()}")
