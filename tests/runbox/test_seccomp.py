"""The run box's seccomp filter: what it compiles to, and what it does to real programs.

Two halves. The first runs the compiled filter (for x86_64 and for aarch64) on made-up system
calls in a small classic-BPF interpreter, so the aarch64 filter is checked here too. The second
runs bubblewrap with the filter, as the launcher will: every denial is tried once without the
filter as well, to show the operation really works there and that the filter is what stops
it; and the languages' ordinary work must still run under it.
"""

import errno
import os
import shutil
import struct
import subprocess
import textwrap

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from runbox import seccomp

ALLOW = seccomp.ACT_ALLOW
KILL = seccomp.ACT_KILL_PROCESS
EPERM = seccomp.errno_action(errno.EPERM)
EAFNOSUPPORT = seccomp.errno_action(errno.EAFNOSUPPORT)
ENOSYS = seccomp.errno_action(errno.ENOSYS)

# The kernel's numbers (arch/x86/entry/syscalls/syscall_64.tbl, include/uapi/asm-generic/
# unistd.h), written out here rather than asked of libseccomp, which the filter comes from.
NR = {
    "x86_64": {
        "read": 0, "write": 1, "ioctl": 16, "getpid": 39, "clone": 56, "fork": 57,
        "personality": 135, "mount": 165, "umount2": 166, "ptrace": 101, "unshare": 272,
        "setns": 308, "bpf": 321, "keyctl": 250, "perf_event_open": 298, "userfaultfd": 323,
        "io_uring_setup": 425, "clone3": 435, "openat": 257, "iopl": 172, "execve": 59,
        "pivot_root": 155, "fsopen": 430, "kexec_load": 246, "process_vm_readv": 310,
        "get_mempolicy": 239, "seccomp": 317, "landlock_create_ruleset": 444,
        "socket": 41, "socketpair": 53,
    },
    "aarch64": {
        "read": 63, "write": 64, "ioctl": 29, "getpid": 172, "clone": 220,
        "personality": 92, "mount": 40, "umount2": 39, "ptrace": 117, "unshare": 97,
        "setns": 268, "bpf": 280, "keyctl": 219, "perf_event_open": 241, "userfaultfd": 282,
        "io_uring_setup": 425, "clone3": 435, "openat": 56, "execve": 221,
        "pivot_root": 41, "fsopen": 430, "kexec_load": 104, "process_vm_readv": 270,
        "get_mempolicy": 236, "seccomp": 277, "landlock_create_ruleset": 444,
        "socket": 198, "socketpair": 199,
    },
    "arm": {  # arch/arm/tools/syscall.tbl (EABI)
        "read": 3, "write": 4, "ioctl": 54, "getpid": 20, "clone": 120,
        "personality": 136, "mount": 21, "umount2": 52, "ptrace": 26, "unshare": 337,
        "setns": 375, "bpf": 386, "keyctl": 311, "perf_event_open": 364, "userfaultfd": 388,
        "io_uring_setup": 425, "clone3": 435, "openat": 322, "execve": 11,
        "pivot_root": 218, "fsopen": 430, "kexec_load": 347, "process_vm_readv": 376,
        "get_mempolicy": 320, "seccomp": 383, "landlock_create_ruleset": 444,
        "socket": 281, "socketpair": 288,
    },
}  # fmt: skip
AUDIT_ARCH = {"x86_64": 0xC000003E, "aarch64": 0xC00000B7, "arm": 0x40000028}
AUDIT_ARCH_I386, AUDIT_ARCH_X32, AUDIT_ARCH_ARM = 0x40000003, 0x4000003E, 0x40000028
X32_SYSCALL_BIT = 0x40000000
SIGCHLD = 17
FORK_FLAGS = 0x01200000 | SIGCHLD  # glibc's fork: CLONE_CHILD_SETTID | CLONE_CHILD_CLEARTID
THREAD_FLAGS = 0x003D0F00  # glibc's pthread_create


def run_bpf(program: bytes, nr: int, arch: int, args=(0,) * 6) -> int:
    """What a classic BPF seccomp program returns for one system call (the opcodes
    libseccomp emits; anything else fails the test)."""
    args = tuple(args) + (0,) * (6 - len(args))
    data = struct.pack("<iIQ6Q", nr, arch, 0, *(a & (2**64 - 1) for a in args))
    insns = [struct.unpack_from("=HBBI", program, i) for i in range(0, len(program), 8)]
    acc, pc = 0, 0
    while True:
        code, jt, jf, k = insns[pc]
        pc += 1
        if code == 0x20:  # ld [k]
            acc = struct.unpack_from("<I", data, k)[0]
        elif code == 0x54:  # and #k
            acc &= k
        elif code == 0x05:  # ja
            pc += k
        elif code in (0x15, 0x25, 0x35, 0x45):  # jeq, jgt, jge, jset #k
            hit = {0x15: acc == k, 0x25: acc > k, 0x35: acc >= k, 0x45: bool(acc & k)}[code]
            pc += jt if hit else jf
        elif code == 0x06:  # ret #k
            return k
        else:
            raise AssertionError(f"opcode {code:#x} not understood")


ARCHES = ["x86_64", "aarch64", "arm"]


def decide(arch, name, *args):
    return run_bpf(seccomp.filter_bytes(arch), NR[arch][name], AUDIT_ARCH[arch], args)


@pytest.mark.parametrize("arch", ARCHES)
def test_compiles_for_both_architectures(arch):
    program = seccomp.filter_bytes(arch)
    assert len(program) % 8 == 0 and 0 < len(program) // 8 < 4096  # BPF_MAXINSNS
    assert seccomp.filter_bytes(arch) is program  # cached


DECISIONS = [
        ("read", (), ALLOW), ("write", (), ALLOW), ("openat", (), ALLOW),
        ("execve", (), ALLOW), ("getpid", (), ALLOW), ("get_mempolicy", (), ALLOW),
        ("seccomp", (), ALLOW), ("landlock_create_ruleset", (), ALLOW),
        ("mount", (), EPERM), ("umount2", (), EPERM), ("pivot_root", (), EPERM),
        ("fsopen", (), EPERM), ("ptrace", (), EPERM), ("process_vm_readv", (), EPERM),
        ("bpf", (), EPERM), ("keyctl", (), EPERM), ("perf_event_open", (), EPERM),
        ("userfaultfd", (), EPERM), ("io_uring_setup", (), EPERM), ("kexec_load", (), EPERM),
        ("setns", (), EPERM), ("clone3", (), ENOSYS),
        ("clone", (FORK_FLAGS,), ALLOW), ("clone", (THREAD_FLAGS,), ALLOW),
        ("clone", (SIGCHLD | 0x10000000,), EPERM), ("clone", (THREAD_FLAGS | 0x20000,), EPERM),
        ("clone", (SIGCHLD | 0x40000000,), EPERM), ("clone", (SIGCHLD | 0x02000000,), EPERM),
        ("clone", (0xFFFFFFFF_00000000 | SIGCHLD,), ALLOW),  # the kernel ignores the top half
        ("clone", (0xFFFFFFFF_00000000 | 0x20000000,), EPERM),
        ("unshare", (0x400,), ALLOW), ("unshare", (0x200,), ALLOW),  # CLONE_FILES, CLONE_FS
        ("unshare", (0,), ALLOW), ("unshare", (0x10000000,), EPERM),
        ("unshare", (0x80,), EPERM), ("unshare", (0x40000000,), EPERM),
        ("unshare", (0x08000000 | 0x400,), EPERM), ("unshare", (0x7E0200A0,), EPERM),
        ("ioctl", (1, 0x5401), ALLOW),  # TCGETS
        ("ioctl", (1, 0x5412), EPERM), ("ioctl", (1, 0xDEAD0000_00005412), EPERM),  # TIOCSTI
        ("ioctl", (1, 0x541C), EPERM),  # TIOCLINUX
        # Unix, IPv4, IPv6, netlink; not vsock, packet, AF_ALG, AF_UNSPEC, nor a top half
        ("socket", (1,), ALLOW), ("socket", (2,), ALLOW), ("socket", (10,), ALLOW),
        ("socket", (16,), ALLOW), ("socket", (40,), EAFNOSUPPORT),
        ("socket", (17,), EAFNOSUPPORT), ("socket", (38,), EAFNOSUPPORT),
        ("socket", (0,), EAFNOSUPPORT), ("socket", (3,), EAFNOSUPPORT),
        ("socket", (0xFFFFFFFF_00000001,), EAFNOSUPPORT),
        ("socketpair", (1,), ALLOW), ("socketpair", (40,), EAFNOSUPPORT),
]  # fmt: skip


@pytest.mark.parametrize(
    "arch, name, args, action",
    [  # arm's arguments are 32 bits wide: the cases with a top half are not arm's
        (arch, *case)
        for arch in ARCHES
        for case in DECISIONS
        if not (arch == "arm" and any(a >= 2**32 for a in case[1]))
    ],
)
def test_decisions(arch, name, args, action):
    assert decide(arch, name, *args) == action


def test_x86_only_calls():
    assert decide("x86_64", "iopl") == EPERM
    assert "iopl" not in NR["aarch64"]  # none there: skipped, not an error
    assert decide("x86_64", "fork") == ALLOW


@pytest.mark.parametrize(
    "arch, foreign",
    [("x86_64", AUDIT_ARCH_I386), ("x86_64", AUDIT_ARCH_X32), ("x86_64", AUDIT_ARCH["aarch64"]),
     ("aarch64", AUDIT_ARCH_ARM), ("aarch64", AUDIT_ARCH["x86_64"]),
     ("arm", AUDIT_ARCH["aarch64"]), ("arm", AUDIT_ARCH_I386)],
)  # fmt: skip
def test_another_abi_is_killed(arch, foreign):
    program = seccomp.filter_bytes(arch)
    for nr in (0, 1, 20, 39, NR[arch]["getpid"], 310):
        assert run_bpf(program, nr, foreign) == KILL


def test_x32_numbers_are_killed():
    program = seccomp.filter_bytes("x86_64")
    for name in ("getpid", "unshare", "mount", "read"):
        nr = X32_SYSCALL_BIT | NR["x86_64"][name]
        assert run_bpf(program, nr, AUDIT_ARCH["x86_64"]) == KILL


@pytest.mark.parametrize("arch", ARCHES)
@pytest.mark.parametrize("value", [*seccomp.PERSONALITY_ALLOWED])
def test_personality_allowed(arch, value):
    assert decide(arch, "personality", value) == ALLOW


@pytest.mark.parametrize("arch", ARCHES)
def test_personality_others_denied(arch):
    values = [1 << i for i in range(64)] + [
        0x0040000, 0x0040008, 0x0400000, 0x80000000, 0x80040000, 0xFFFFFFFE, 0x7FFFFFFF,
        0x1_00000000, 0xFFFFFFFF_FFFFFFFF, 0x1_FFFFFFFF, 0x20009, 0x4, 0xFF,
    ]  # fmt: skip
    for value in values:
        if arch == "arm" and value >= 2**32:
            continue
        if value not in seccomp.PERSONALITY_ALLOWED:
            assert decide(arch, "personality", value) == EPERM, hex(value)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.integers(0, 2**32 - 1), st.integers(0, 2**64 - 1)))
def test_personality_any_value(value):
    expected = ALLOW if value in seccomp.PERSONALITY_ALLOWED else EPERM
    assert decide("x86_64", "personality", value) == expected


def test_filter_fd():
    fd = seccomp.open_filter_fd()
    try:
        assert os.lseek(fd, 0, os.SEEK_CUR) == 0
        assert not os.get_inheritable(fd)
        assert os.read(fd, 1 << 20) == seccomp.filter_bytes()
        with pytest.raises(PermissionError):  # sealed
            os.pwrite(fd, b"\0" * 8, 0)
        assert seccomp.bwrap_args(fd) == ["--seccomp", str(fd)]
    finally:
        os.close(fd)


# ---- In bubblewrap ----------------------------------------------------------------------

BWRAP = shutil.which("bwrap")
NATIVE = seccomp.native_arch()
needs_box = pytest.mark.skipif(
    BWRAP is None or os.geteuid() != 0, reason="needs bubblewrap and root"
)
PYTHON = "/usr/bin/python3"


def box(argv, *, filtered=True, rootless=False, timeout=30):
    """Run argv in bubblewrap as the launcher would (root-launched), or rootless-style: bwrap
    itself unprivileged, in a user namespace of its own, as uid 1000."""
    fd = seccomp.open_filter_fd()
    try:
        cmd = [
            BWRAP, "--die-with-parent", "--ro-bind", "/", "/", "--dev", "/dev",
            "--proc", "/proc", "--tmpfs", "/tmp", "--unshare-pid", "--unshare-ipc",
            *(seccomp.bwrap_args(fd) if filtered else []), "--", *argv,
        ]  # fmt: skip
        if rootless:
            cmd[1:1] = ["--unshare-user", "--uid", "1000", "--gid", "1000"]
            cmd[:0] = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", "--"]
        return subprocess.run(
            cmd, pass_fds=(fd,), capture_output=True, text=True, timeout=timeout,
            env={"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8", "HOME": "/tmp"},
        )  # fmt: skip
    finally:
        os.close(fd)


# Each probe prints "ok" if the call worked, else its errno's name.
PROBE = textwrap.dedent(
    """
    import ctypes, errno, os, struct, subprocess, sys
    libc = ctypes.CDLL(None, use_errno=True)
    libc.syscall.restype = ctypes.c_long
    NR = %r
    def sys_(name, *args):
        args = [ctypes.c_long(a) if isinstance(a, int) else a for a in args]
        return libc.syscall(ctypes.c_long(NR[name]), *args)
    def ptrace():
        child = subprocess.Popen(["sleep", "10"])
        try:
            return libc.ptrace(16, child.pid, None, None)  # PTRACE_ATTACH
        finally:
            child.kill()
    def bpf():  # an array map of one int
        attr = ctypes.create_string_buffer(struct.pack("IIII", 2, 4, 4, 1), 128)
        return sys_("bpf", 0, attr, 128)
    def keyctl():  # KEYCTL_GET_KEYRING_ID of the session keyring, made if need be
        return sys_("keyctl", 0, -3, 1)
    def perf_event_open():  # a software task clock for this process
        attr = ctypes.create_string_buffer(struct.pack("IIQ", 1, 128, 1), 128)
        return sys_("perf_event_open", attr, 0, -1, -1, 0)
    def userfaultfd():
        return sys_("userfaultfd", os.O_CLOEXEC)
    def setns():
        return libc.setns(os.open("/proc/1/ns/net", os.O_RDONLY), 0)
    def personality():  # ADDR_NO_RANDOMIZE
        return libc.personality(0x0040000)
    def forked(rc):
        if rc == 0:
            os._exit(0)
        if rc > 0:
            os.waitpid(rc, 0)
        return rc
    def clone_newuser():
        return forked(sys_("clone", 0x10000000 | 17, 0, 0, 0, 0))
    def clone3():
        args = ctypes.create_string_buffer(struct.pack("QQQQQQQQ", 0, 0, 0, 0, 17, 0, 0, 0))
        return forked(sys_("clone3", args, 64))
    def vsock():  # not network-namespaced: the host's vsock ports, whatever the box's network
        import socket
        try:
            socket.socket(40, socket.SOCK_STREAM).close()
            return 0
        except OSError as e:
            ctypes.set_errno(e.errno)
            return -1
    def x32():  # getpid by its x32 number
        return sys_("x32_getpid")
    def i386():  # getpid through int 0x80
        import mmap
        code = bytes.fromhex("b814000000cd80c3")  # mov eax, 20; int 0x80; ret
        mem = mmap.mmap(-1, 4096, prot=mmap.PROT_READ | mmap.PROT_WRITE | mmap.PROT_EXEC)
        mem.write(code)
        addr = ctypes.addressof(ctypes.c_char.from_buffer(mem))
        rc = ctypes.CFUNCTYPE(ctypes.c_int)(addr)()
        return rc if rc >= 0 else (ctypes.set_errno(-rc) or -1)
    rc = globals()[sys.argv[1]]()
    print("ok" if rc >= 0 else errno.errorcode[ctypes.get_errno()])
    """
)


def probe(op, **kw):
    nr = dict(NR[NATIVE], x32_getpid=X32_SYSCALL_BIT | NR["x86_64"]["getpid"])
    return box([PYTHON, "-c", PROBE % (nr,), op], **kw)


CONTROLLED = ["filtered", "unfiltered (control)"]


@needs_box
@pytest.mark.parametrize("filtered", [True, False], ids=CONTROLLED)
@pytest.mark.parametrize(
    "argv",
    [["unshare", "-Ur", "true"], ["unshare", "-n", "true"], ["unshare", "-m", "true"],
     ["sh", "-c", "mkdir /tmp/x && mount -t tmpfs x /tmp/x"]],
    ids=["unshare -Ur", "unshare -n", "unshare -m", "mount"],
)  # fmt: skip
def test_commands_denied(argv, filtered):
    done = box(argv, filtered=filtered)
    if filtered:
        assert done.returncode != 0
        assert "Operation not permitted" in done.stderr or "permission denied" in done.stderr
    else:
        assert done.returncode == 0, done.stderr


OPS = [
    ("ptrace", "EPERM"), ("bpf", "EPERM"), ("keyctl", "EPERM"), ("perf_event_open", "EPERM"),
    ("userfaultfd", "EPERM"), ("setns", "EPERM"), ("personality", "EPERM"),
    ("clone_newuser", "EPERM"), ("clone3", "ENOSYS"), ("vsock", "EAFNOSUPPORT"),
]  # fmt: skip


@needs_box
@pytest.mark.parametrize("filtered", [True, False], ids=CONTROLLED)
@pytest.mark.parametrize("op, denied", OPS, ids=[op for op, _ in OPS])
def test_calls_denied(op, denied, filtered):
    done = probe(op, filtered=filtered)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == (denied if filtered else "ok")


@needs_box
@pytest.mark.skipif(NATIVE != "x86_64", reason="x86_64's other ABIs")
@pytest.mark.parametrize("filtered", [True, False], ids=CONTROLLED)
@pytest.mark.parametrize("op", ["x32", "i386"])
def test_other_abis_killed(op, filtered):
    done = probe(op, filtered=filtered)
    if filtered:
        assert done.returncode in (-31, 128 + 31), (done.returncode, done.stderr)  # SIGSYS
    else:  # the kernel answers (ENOSYS where it has no x32, say): nothing is killed
        assert done.returncode == 0, done.stderr


@needs_box
@pytest.mark.parametrize("filtered", [True, False], ids=CONTROLLED)
@pytest.mark.parametrize(
    "argv", [["unshare", "-Ur", "true"], [PYTHON, "-c", PROBE % (NR[NATIVE],), "ptrace"]],
    ids=["unshare -Ur", "ptrace"],
)  # fmt: skip
def test_rootless_denied(argv, filtered):
    done = box(argv, filtered=filtered, rootless=True)
    if done.returncode != 0 and "setting up uid map" in done.stderr + done.stdout:
        pytest.skip("no unprivileged user namespaces here")
    if filtered:
        assert done.returncode != 0 or done.stdout.strip() == "EPERM"
        assert "Operation not permitted" in done.stderr or done.stdout.strip() == "EPERM"
    else:
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() in ("", "ok")


WORK = {
    "python threads": [PYTHON, "-c", (
        "import threading, concurrent.futures as f\n"
        "with f.ThreadPoolExecutor(4) as ex: print(sum(ex.map(lambda x: x * x, range(100))))"
    )],
    "python subprocess": [PYTHON, "-c", (
        "import subprocess; print(subprocess.run(['echo', 'hi'], capture_output=True,"
        " text=True).stdout.strip())"
    )],
    "python multiprocessing": [PYTHON, "-c", (
        "import multiprocessing as m\n"
        "if __name__ == '__main__':\n"
        "    with m.Pool(2) as p: print(sum(p.map(abs, range(-5, 5))))"
    )],
    "python socket": [PYTHON, "-c", (
        "import socket; s = socket.socket(); s.bind(('127.0.0.1', 0)); s.listen();"
        " u = socket.socket(socket.AF_UNIX); a, b = socket.socketpair(); a.send(b'x');"
        " print(b.recv(1).decode())"
    )],
    "python asyncio": [PYTHON, "-c", (
        "import asyncio\nasync def main():\n"
        "    p = await asyncio.create_subprocess_exec('true'); print(await p.wait())\n"
        "asyncio.run(main())"
    )],
    "perl": ["perl", "-e", "my $p = fork; if (!$p) { exit 0 } waitpid($p, 0); print 1+1"],
    "ruby": ["ruby", "-e", "t = Thread.new { 6 * 7 }; puts t.value; puts `echo hi`"],
    "lua": ["lua5.4", "-e", "print(io.popen('echo hi'):read('a'))"],
    "node": ["node", "-e", (
        "require('child_process').execSync('true');"
        "require('fs').readFile('/etc/hostname', () => console.log(1))"
    )],
    "node worker": ["node", "-e", (
        "const {Worker} = require('worker_threads');"
        "new Worker('require(\"worker_threads\").parentPort.postMessage(2)', {eval: true})"
        ".on('message', m => console.log(m))"
    )],
    "tcl": ["tclsh"],  # the script on stdin: see below
    "sh": ["sh", "-c", "echo hello world | tr a-z A-Z | wc -w; (sleep 0; echo sub) & wait"],
    "prlimit and setpriv": ["setpriv", "--reuid=1234", "--regid=1234", "--clear-groups",
                            "--no-new-privs", "--", "prlimit", "--nofile=64", "id", "-u"],
}  # fmt: skip
TCL = "puts [exec echo hi]; after 10; puts [expr {6 * 7}]\n"


@needs_box
@pytest.mark.parametrize("name", list(WORK))
def test_ordinary_work_runs(name):
    argv = WORK[name]
    if shutil.which(argv[0], path="/usr/bin:/bin") is None:
        pytest.skip(f"{argv[0]} not installed")
    if name == "tcl":
        argv = ["sh", "-c", f"printf '%s' '{TCL.strip()}' | tclsh"]
    done = box(argv)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip(), done.stderr


@needs_box
def test_filter_in_force_and_its_fd_closed():
    done = box(["sh", "-c", "grep -E '^(Seccomp|NoNewPrivs):' /proc/self/status; ls /proc/self/fd"])
    assert done.returncode == 0, done.stderr
    assert "Seccomp:\t2" in done.stdout and "NoNewPrivs:\t1" in done.stdout
    fds = {line for line in done.stdout.split() if line.isdigit()}
    assert fds <= {"0", "1", "2", "3"}  # 3: ls's own listing


def test_a_misspelt_name_is_an_error(monkeypatch):
    monkeypatch.setitem(seccomp.DENIED, "mistakes", ("unshar",))
    with pytest.raises(seccomp.SeccompUnavailable, match="unshar"):
        seccomp.describe("x86_64")
