"""The rootless box's first process: run by the system's python3 (-I -S), standard library only.

An agent that is not root cannot enter a run's namespaces, so this does from the inside what
bubblewrap and the agent do as root. util-linux `unshare` starts it in new user (it is root
there, and nowhere else), mount, pid, network, ipc and uts namespaces. It then

1. reads the box's spec from the agent on the control socket (fd given as argv[1]);
2. builds the run's filesystem on a tmpfs and pivots into it: /usr, /etc and the libraries
   read-only, the Robot API clients and socket, /proc of the run's pid namespace, a few
   devices, a /tmp of `tmp_mb` and the run's folder, a tmpfs of `disk_mb`;
3. binds the run's 127.0.0.1 services and hands their sockets to the agent, then waits for
   its go, which brings the run's program, command line and environment (by then the agent
   has put this process in the run's cgroup, where it has one; the box may wait long: the
   agent makes one ahead of its runs);
4. writes the program into the run's folder, enters a nested user namespace where the run
   is uid 1000 and nothing more, applies the seccomp filter, forks the program and stays as
   the pid namespace's init: it reaps, and exits as the program did (128 + N for a signal,
   as bubblewrap reports it).
"""

import base64
import ctypes
import json
import os
import resource
import signal
import socket
import sys

MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC = 0x1, 0x2, 0x4, 0x8
MS_REMOUNT, MS_BIND, MS_REC, MS_PRIVATE = 0x20, 0x1000, 0x4000, 0x40000
MNT_DETACH = 0x2
CLONE_NEWUSER = 0x10000000
PR_SET_NO_NEW_PRIVS, PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 38, 22, 2
PR_SET_PDEATHSIG = 1
ST_FLAGS = {os.ST_NOSUID: MS_NOSUID, os.ST_NODEV: MS_NODEV, os.ST_NOEXEC: MS_NOEXEC}
DEVICES = ("null", "zero", "full", "random", "urandom", "tty")
RUN_UID = 1000
PIVOT_ROOT = {"x86_64": 155, "aarch64": 41, "armv7l": 218, "armv6l": 218}  # syscall numbers
ROOT = "/tmp"  # the staging folder, in this mount namespace only

libc = ctypes.CDLL(None, use_errno=True)


def check(result: int, what: str) -> None:
    if result != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"{what}: {os.strerror(err)}")


def mount(source: str, target: str, fstype: str | None, flags: int, data: str = "") -> None:
    check(
        libc.mount(source.encode(), target.encode(), fstype.encode() if fstype else None,
                   ctypes.c_ulong(flags), data.encode() if data else None),
        f"mount {target}",
    )  # fmt: skip


class Source:
    """A path to bind, held open from before the staging tmpfs may cover where it lies."""

    def __init__(self, path: str):
        self.path, self.is_dir = path, os.path.isdir(path)
        self.fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
        self.flags = sum(flag for st, flag in ST_FLAGS.items() if os.statvfs(self.fd).f_flag & st)


def bind(source: Source, target: str, readonly: bool) -> None:
    if source.is_dir:
        os.makedirs(target, exist_ok=True)
    else:
        os.makedirs(os.path.dirname(target), exist_ok=True)
        open(target, "a").close()
    held = f"/proc/self/fd/{source.fd}"
    mount(held, target, None, MS_BIND | MS_REC)
    if readonly:  # a remount in a user namespace must keep the flags it cannot clear
        mount(held, target, None, MS_REMOUNT | MS_BIND | MS_RDONLY | source.flags)
    os.close(source.fd)


def tmpfs(target: str, size_mb: int, mode: str) -> None:
    os.makedirs(target, exist_ok=True)
    mount("tmpfs", target, "tmpfs", MS_NOSUID | MS_NODEV, f"size={size_mb}m,mode={mode}")


def build_root(spec: dict) -> None:
    mount("none", "/", None, MS_REC | MS_PRIVATE)
    links = {p: os.readlink(p) for p in spec["readonly"] if os.path.islink(p)}
    readonly = [Source(p) for p in spec["readonly"] if p not in links and os.path.exists(p)]
    clients, api = Source(spec["clients"]), Source(spec["api_dir"])
    devices = [Source("/dev/" + device) for device in DEVICES if os.path.exists("/dev/" + device)]
    mount("tmpfs", ROOT, "tmpfs", MS_NOSUID | MS_NODEV, "mode=0755,size=1m")
    for source in readonly:
        bind(source, ROOT + source.path, readonly=True)
    for path, target in links.items():
        os.symlink(target, ROOT + path)
    bind(clients, ROOT + spec["clients_at"], readonly=True)
    # Read-only: the robot's, shared by its runs (connect() needs no write to the mount).
    bind(api, ROOT + spec["api_at"], readonly=True)
    for device in devices:
        bind(device, ROOT + device.path, readonly=False)
    for name, target in (("fd", "/proc/self/fd"), ("stdin", "/proc/self/fd/0"),
                         ("stdout", "/proc/self/fd/1"), ("stderr", "/proc/self/fd/2")):  # fmt: skip
        os.symlink(target, f"{ROOT}/dev/{name}")
    if spec.get("resolv_conf"):
        own_resolv_conf(spec["resolv_conf"])
    tmpfs(ROOT + "/dev/shm", spec["tmp_mb"], "1777")
    tmpfs(ROOT + "/tmp", spec["tmp_mb"], "1777")
    tmpfs(ROOT + spec["home"], spec["disk_mb"], "1777")
    os.makedirs(ROOT + "/proc", exist_ok=True)
    mount("proc", ROOT + "/proc", "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC)
    os.makedirs(ROOT + "/.old", exist_ok=True)
    number = PIVOT_ROOT[os.uname().machine]
    check(libc.syscall(number, ROOT.encode(), (ROOT + "/.old").encode()), "pivot_root")
    os.chdir("/")
    check(libc.umount2(b"/.old", MNT_DETACH), "umount the old root")
    os.rmdir("/.old")
    mount("none", "/", None, MS_REMOUNT | MS_BIND | MS_RDONLY | MS_NOSUID | MS_NODEV)


def own_resolv_conf(resolv: dict) -> None:
    """A `full` run's resolv.conf (the NAT's DNS forwarder), where the box's /etc/resolv.conf
    leads (runbox.isolation.resolv_conf_place): over the host's file, or in folders made."""
    for folder in resolv["folders"]:
        os.makedirs(ROOT + folder, exist_ok=True)
        os.chmod(ROOT + folder, 0o755)  # whatever the agent's umask
    target = ROOT + resolv["path"]
    staged = ROOT + "/.resolv.conf"
    with open(os.open(staged, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644), "w") as file:
        file.write(resolv["text"])
    os.chmod(staged, 0o644)
    if not os.path.exists(target):  # in a folder of the box's own
        os.rename(staged, target)
        return
    mount(staged, target, None, MS_BIND)
    mount(staged, target, None, MS_REMOUNT | MS_BIND | MS_RDONLY | MS_NOSUID | MS_NODEV)
    os.unlink(staged)


def loopback_up() -> None:
    import fcntl
    import struct

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        request = struct.pack("16sH14s", b"lo", 0, b"")
        flags = struct.unpack("16sH14s", fcntl.ioctl(s, 0x8913, request))[1]
        fcntl.ioctl(s, 0x8914, struct.pack("16sH14s", b"lo", flags | 0x1, b""))


def bind_services(services: list[str]) -> list[socket.socket]:
    loopback_up()
    made = []
    for service in services:
        proto, port = service.split(":")
        sock = socket.socket(
            socket.AF_INET, socket.SOCK_STREAM if proto == "tcp" else socket.SOCK_DGRAM
        )
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", int(port)))
        if proto == "tcp":
            sock.listen(64)
        made.append(sock)
    return made


def become_the_run() -> None:
    """A nested user namespace where the run is RUN_UID: it keeps no power over the mounts
    and the network this process set up (they belong to the outer one)."""
    check(libc.unshare(CLONE_NEWUSER), "unshare the run's user namespace")
    for name, line in (("setgroups", "deny"), ("uid_map", f"{RUN_UID} 0 1"),
                       ("gid_map", f"{RUN_UID} 0 1")):  # fmt: skip
        with open(f"/proc/self/{name}", "w") as file:
            file.write(line)
    os.setresgid(RUN_UID, RUN_UID, RUN_UID)
    os.setresuid(RUN_UID, RUN_UID, RUN_UID)


class SockFilter(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_char_p)]


def apply_seccomp(program: bytes) -> None:
    check(libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0), "no_new_privs")
    if program:
        fprog = SockFilter(len(program) // 8, program)
        check(libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.byref(fprog), 0, 0),
              "seccomp")  # fmt: skip


def write_program(home: str, run: dict) -> None:
    name = run["filename"]
    if not name or "/" in name or name in (".", ".."):
        raise OSError(f"not a plain file name: {name!r}")
    fd = os.open(os.path.join(home, name), os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    with open(fd, "wb") as file:
        file.write(base64.b64decode(run["source"]))


def read_fd(fd: int) -> bytes:
    chunks = []
    while chunk := os.read(fd, 1 << 16):
        chunks.append(chunk)
    os.close(fd)
    return b"".join(chunks)


def serve_as_init(child: int) -> int:
    """Reap every orphan of the run; the box ends when the program does."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the agent signals the program itself
    while True:
        pid, status = os.wait()
        if pid == child:
            return os.waitstatus_to_exitcode(status)


def main() -> int:
    # Inherited from the agent: the program must not inherit it in turn (the agent's end).
    os.set_inheritable(int(sys.argv[1]), False)
    control = socket.socket(fileno=int(sys.argv[1]))
    control.setblocking(True)  # whatever the file's flags came as
    reader = control.makefile("rb")
    spec = json.loads(reader.readline())
    seccomp = read_fd(spec["seccomp_fd"]) if spec.get("seccomp_fd") is not None else b""
    build_root(spec)
    socket.sethostname("robot")  # its own uts namespace: the host's name is not its business
    sockets = bind_services(spec["services"])
    fds = [s.fileno() for s in sockets]
    control.sendmsg([b"ready\n"], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, bytes(
        b for fd in fds for b in fd.to_bytes(4, sys.byteorder)))] if fds else [])  # fmt: skip
    for sock in sockets:
        sock.close()
    answer = reader.readline()
    try:
        run = json.loads(answer)["go"]
        argv, env = [str(a) for a in run["argv"]], {str(k): str(v) for k, v in run["env"].items()}
    except (ValueError, KeyError, TypeError, AttributeError):
        print(f"robotide: the agent did not let the run start ({answer[:80]!r})", file=sys.stderr)
        return 125
    reader.close()  # the socket closes with the last of the two
    control.close()
    write_program(spec["home"], run)
    become_the_run()
    os.chdir(spec["home"])
    child = os.fork()
    if child == 0:
        try:
            for limit, soft, hard in spec["rlimits"]:
                resource.setrlimit(limit, (soft, hard))
            apply_seccomp(seccomp)
            os.execvpe(argv[0], argv, env)
        except OSError as exc:
            print(f"robotide: cannot start {argv[0]}: {exc}", file=sys.stderr)
        os._exit(127)
    code = serve_as_init(child)
    return 128 - code if code < 0 else code


if __name__ == "__main__":
    try:
        sys.exit(main())
    except OSError as exc:
        print(f"robotide: the run's box could not be made: {exc}", file=sys.stderr)
        sys.exit(125)
