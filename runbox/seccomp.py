"""The run box's seccomp filter: the system calls a run may not make.

bubblewrap loads it (``--seccomp FD``: a compiled ``struct sock_filter`` array read from FD)
as the last thing before it executes the command inside the box, after it has built the
namespaces and mounts; so setpriv, prlimit and the program all run under it, and nothing
inside can take it off (filters are inherited across fork and exec and can only be added to).

What it denies, with EPERM so a program gets a clear error rather than a crash:

- new namespaces: ``unshare`` and ``clone`` with any ``CLONE_NEW*`` flag, ``setns``;
  ``clone3`` answers ENOSYS (its flags are in memory a filter cannot read), so libc falls back
  to ``clone``, as Docker and Flatpak do;
- mounting: ``mount``, ``umount2``, ``pivot_root`` and the new mount API;
- looking into other processes: ``ptrace``, ``process_vm_readv``/``writev``, ``kcmp``,
  ``pidfd_getfd``;
- kernel attack surface an ordinary program has no use for: ``bpf``, ``perf_event_open``,
  ``userfaultfd``, ``io_uring_*``, the keyring, modules, ``kexec``, ``iopl``/``ioperm``,
  ``modify_ldt``, swap, ``reboot``, ``acct``, quotas, file handles, ``syslog``, ``vhangup``,
  setting the clock, NUMA memory policy, and Docker's other default denials;
- ``personality`` other than Linux / Linux32 (optionally with UNAME26) and the query;
- ``ioctl(TIOCSTI)`` and ``ioctl(TIOCLINUX)``, which push input into a terminal (as Flatpak);
- sockets of any family but Unix, IPv4, IPv6 and netlink, with EAFNOSUPPORT (as Flatpak):
  vsock is not network-namespaced (on a virtual machine a run would share the host's vsock
  ports whatever its network), and the rarer families are kernel code a program has no use
  for.

Everything else is allowed. Only the machine's own architecture passes: a system call made
through another ABI (i386 ``int 0x80`` or x32 on x86_64, AArch32 on aarch64) kills the
process, so no compatibility table is a way around the list (and a foreign binary cannot spin
in a loop of failing exits).

The filter is compiled by libseccomp (``libseccomp.so.2``, installed with Debian itself),
called through ctypes: it knows each architecture's system call numbers, adds the
architecture and x32 checks and lays the comparisons out as a binary tree.
"""

import ctypes
import ctypes.util
import errno
import fcntl
import os
import platform
from dataclasses import dataclass
from functools import cache

# The flags of clone(2) and unshare(2) that make a new namespace. CLONE_NEWTIME shares its
# bit with clone's exit signal, so it is only a namespace flag for unshare (and clone3).
CLONE_NEWTIME = 0x00000080
CLONE_NEWNS = 0x00020000
CLONE_NEWCGROUP = 0x02000000
CLONE_NEWUTS = 0x04000000
CLONE_NEWIPC = 0x08000000
CLONE_NEWUSER = 0x10000000
CLONE_NEWPID = 0x20000000
CLONE_NEWNET = 0x40000000
CLONE_NAMESPACES = (
    CLONE_NEWNS, CLONE_NEWCGROUP, CLONE_NEWUTS, CLONE_NEWIPC, CLONE_NEWUSER, CLONE_NEWPID,
    CLONE_NEWNET,
)  # fmt: skip
UNSHARE_NAMESPACES = (CLONE_NEWTIME, *CLONE_NAMESPACES)

TIOCSTI = 0x5412
TIOCLINUX = 0x541C
# socket(2)'s families a run may use: AF_UNIX, AF_INET, AF_INET6, AF_NETLINK.
SOCKET_FAMILIES = (1, 2, 10, 16)

# personality(2) values allowed, as in Docker's profile: PER_LINUX, PER_LINUX32, each with
# UNAME26, and 0xffffffff, which only asks for the current one.
PERSONALITY_QUERY = 0xFFFFFFFF
PERSONALITY_ALLOWED = (0x0, 0x8, 0x20000, 0x20008, PERSONALITY_QUERY)

DENIED = {
    "namespaces": ("setns",),  # unshare and clone: by their flags, below
    "mounts": (
        "mount", "umount", "umount2", "pivot_root", "move_mount", "open_tree", "fsopen",
        "fsmount", "fsconfig", "fspick", "mount_setattr",
    ),
    "other processes": ("ptrace", "process_vm_readv", "process_vm_writev", "kcmp",
                        "pidfd_getfd"),
    "kernel interfaces": (
        "bpf", "perf_event_open", "userfaultfd", "lookup_dcookie", "syslog", "vhangup",
        "fanotify_init", "nfsservctl", "uselib", "ustat", "sysfs", "_sysctl",
    ),
    # io_uring: a large, fast-moving kernel surface with a record of privilege escalations
    # (Google turned it off in ChromeOS, Android and its servers; Docker's profile blocks it
    # since 25.0). The runtimes here use it at most optionally (libuv, Node's, falls back to
    # its thread pool when io_uring_setup fails).
    "io_uring": ("io_uring_setup", "io_uring_enter", "io_uring_register"),
    "keys": ("keyctl", "add_key", "request_key"),
    "modules": ("init_module", "finit_module", "delete_module", "create_module",
                "query_module", "get_kernel_syms"),
    "kexec": ("kexec_load", "kexec_file_load"),
    "hardware": ("iopl", "ioperm", "modify_ldt", "vm86", "vm86old", "pciconfig_iobase",
                 "pciconfig_read", "pciconfig_write"),
    "system": ("swapon", "swapoff", "reboot", "acct", "quotactl", "quotactl_fd"),
    "file handles": ("open_by_handle_at", "name_to_handle_at"),
    "clock": ("settimeofday", "stime", "clock_settime", "clock_settime64", "clock_adjtime",
              "clock_adjtime64"),
    # get_mempolicy stays: it only reads.
    "memory policy": ("mbind", "set_mempolicy", "set_mempolicy_home_node", "migrate_pages",
                      "move_pages"),
}  # fmt: skip

# libseccomp's constants (seccomp.h)
ACT_KILL_PROCESS = 0x80000000
ACT_ALLOW = 0x7FFF0000
ACT_ERRNO = 0x00050000
ATTR_ACT_BADARCH = 2
ATTR_CTL_NNP = 3
ATTR_CTL_OPTIMIZE = 8
NR_SCMP_ERROR = -1
CMP_NE, CMP_LT, CMP_LE, CMP_EQ, CMP_GE, CMP_GT, CMP_MASKED_EQ = range(1, 8)

# The architectures a run may be on: libseccomp's token (the kernel's AUDIT_ARCH_*). "arm"
# is a Raspberry Pi with a 32-bit userland (Raspberry Pi OS 32-bit), whose kernel is often
# 64-bit: what counts is the ABI the programs use, which is libseccomp's own (its native
# architecture), not what uname says.
ARCHES = {"x86_64": 0xC000003E, "aarch64": 0xC00000B7, "arm": 0x40000028}


class SeccompUnavailable(RuntimeError):
    pass


def errno_action(code: int) -> int:
    return ACT_ERRNO | (code & 0xFFFF)


@dataclass(frozen=True)
class Rule:
    """`syscall` gets `action`, always or (`arg` set) when the comparison holds: for
    CMP_MASKED_EQ, ``args[arg] & a == b``; for the others, ``args[arg] <op> a``."""

    syscall: str
    action: int = errno_action(errno.EPERM)
    arg: int | None = None
    op: int = CMP_MASKED_EQ
    a: int = 0
    b: int = 0


def rules() -> list[Rule]:
    """The filter's rules (libseccomp lays them out itself; their order does not matter)."""
    out = [Rule(name) for names in DENIED.values() for name in names]
    out.append(Rule("clone3", errno_action(errno.ENOSYS)))
    out += [Rule("unshare", arg=0, a=flag, b=flag) for flag in UNSHARE_NAMESPACES]
    out += [Rule("clone", arg=0, a=flag, b=flag) for flag in CLONE_NAMESPACES]
    # ioctl's request is an int: its upper half may be anything.
    out += [Rule("ioctl", arg=1, a=0xFFFFFFFF, b=op) for op in (TIOCSTI, TIOCLINUX)]
    out += personality_rules()
    out += socket_rules()
    return out


def socket_rules() -> list[Rule]:
    """socket() and socketpair() of a family not in SOCKET_FAMILIES: EAFNOSUPPORT. The
    others below the highest allowed one by name, everything above it (a top half included)
    by one comparison."""
    refused = errno_action(errno.EAFNOSUPPORT)
    top = max(SOCKET_FAMILIES)
    others = [f for f in range(top) if f not in SOCKET_FAMILIES]
    return [
        rule
        for call in ("socket", "socketpair")
        for rule in (
            *(Rule(call, refused, arg=0, op=CMP_EQ, a=family) for family in others),
            Rule(call, refused, arg=0, op=CMP_GT, a=top),
        )
    ]


def personality_rules() -> list[Rule]:
    """Deny personality(v) unless v is one of PERSONALITY_ALLOWED.

    A libseccomp rule holds one comparison per argument, so "none of these five values" is
    spelled out as rules that each say "this bit set, that bit clear". No allowed value but
    the query has bit 31, and the query has every bit of the low 32, so v is denied when
    - bit 31 is clear and v has a bit no allowed value has, or
    - bit 31 is set and any other bit is clear (all such values but the query), or
    - v has a bit beyond the low 32 (the kernel would truncate it to something unchecked).
    """
    allowed_bits = 0
    for v in PERSONALITY_ALLOWED:
        if v != PERSONALITY_QUERY:
            allowed_bits |= v
    top = 1 << 31
    lower = [1 << i for i in range(31)]
    out = [
        Rule("personality", arg=0, a=bit | top, b=bit) for bit in lower if not bit & allowed_bits
    ]
    out += [Rule("personality", arg=0, a=bit | top, b=top) for bit in lower]
    out.append(Rule("personality", arg=0, op=CMP_GT, a=0xFFFFFFFF))
    return out


class _Cmp(ctypes.Structure):
    _fields_ = [
        ("arg", ctypes.c_uint),
        ("op", ctypes.c_int),
        ("datum_a", ctypes.c_uint64),
        ("datum_b", ctypes.c_uint64),
    ]


@cache
def _lib() -> ctypes.CDLL:
    name = ctypes.util.find_library("seccomp") or "libseccomp.so.2"
    try:
        lib = ctypes.CDLL(name, use_errno=True)
    except OSError as e:
        raise SeccompUnavailable(
            "libseccomp is not installed on this robot computer (apt install libseccomp2)"
        ) from e
    lib.seccomp_init.restype = ctypes.c_void_p
    lib.seccomp_init.argtypes = [ctypes.c_uint32]
    lib.seccomp_release.argtypes = [ctypes.c_void_p]
    lib.seccomp_attr_set.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_uint32]
    lib.seccomp_arch_add.argtypes = [ctypes.c_void_p, ctypes.c_uint32]
    lib.seccomp_arch_remove.argtypes = [ctypes.c_void_p, ctypes.c_uint32]
    lib.seccomp_arch_native.restype = ctypes.c_uint32
    lib.seccomp_syscall_resolve_name_arch.argtypes = [ctypes.c_uint32, ctypes.c_char_p]
    lib.seccomp_syscall_resolve_name.argtypes = [ctypes.c_char_p]
    lib.seccomp_rule_add_array.argtypes = [
        ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int, ctypes.c_uint, ctypes.POINTER(_Cmp),
    ]  # fmt: skip
    lib.seccomp_export_bpf.argtypes = [ctypes.c_void_p, ctypes.c_int]
    lib.seccomp_export_pfc.argtypes = [ctypes.c_void_p, ctypes.c_int]
    return lib


def native_arch() -> str:
    token = _lib().seccomp_arch_native()
    for arch, known in ARCHES.items():
        if token == known:
            return arch
    raise SeccompUnavailable(
        f"no seccomp filter for runs on {platform.machine()} (only {', '.join(ARCHES)})"
    )


def _check(rc: int, what: str) -> None:
    if rc < 0:
        raise SeccompUnavailable(f"libseccomp: {what} failed: {os.strerror(-rc)}")


def _export(arch: str, export: str) -> bytes:
    """Compile the rules for `arch` and return libseccomp's `export` (``bpf`` or ``pfc``)."""
    lib = _lib()
    token = ARCHES[arch]
    ctx = lib.seccomp_init(ACT_ALLOW)
    if not ctx:
        raise SeccompUnavailable("libseccomp: seccomp_init failed")
    try:
        # Another ABI's system call: the process is killed (see the module's notes).
        _check(lib.seccomp_attr_set(ctx, ATTR_ACT_BADARCH, ACT_KILL_PROCESS), "badarch")
        _check(lib.seccomp_attr_set(ctx, ATTR_CTL_NNP, 0), "nnp")  # bwrap loads it, not us
        lib.seccomp_attr_set(ctx, ATTR_CTL_OPTIMIZE, 2)  # a binary tree; libseccomp >= 2.5
        if token != lib.seccomp_arch_native():
            _check(lib.seccomp_arch_add(ctx, token), f"adding {arch}")
            _check(lib.seccomp_arch_remove(ctx, lib.seccomp_arch_native()), "native arch")
        for rule in rules():
            here = lib.seccomp_syscall_resolve_name_arch(token, rule.syscall.encode())
            if here == NR_SCMP_ERROR:  # a name libseccomp has never heard of: a mistake
                raise SeccompUnavailable(f"libseccomp does not know a syscall {rule.syscall}")
            if here < 0:
                continue  # not a system call on this architecture (iopl on aarch64)
            # The number as libseccomp knows it here; it translates it for `arch`.
            nr = lib.seccomp_syscall_resolve_name(rule.syscall.encode())
            if rule.arg is None:
                rc = lib.seccomp_rule_add_array(ctx, rule.action, nr, 0, None)
            else:
                cmp = (_Cmp * 1)(_Cmp(rule.arg, rule.op, rule.a, rule.b))
                rc = lib.seccomp_rule_add_array(ctx, rule.action, nr, 1, cmp)
            _check(rc, f"rule for {rule.syscall}")
        r, w = os.pipe()
        try:
            fn = lib.seccomp_export_bpf if export == "bpf" else lib.seccomp_export_pfc
            _check(fn(ctx, w), f"export {export}")
            os.close(w)
            w = -1
            chunks = []
            while chunk := os.read(r, 65536):
                chunks.append(chunk)
            return b"".join(chunks)
        finally:
            os.close(r)
            if w >= 0:
                os.close(w)
    finally:
        lib.seccomp_release(ctx)


@cache
def filter_bytes(arch: str | None = None) -> bytes:
    """The compiled filter (``struct sock_filter[]``) for `arch`, by default this machine's."""
    return _export(arch or native_arch(), "bpf")


def describe(arch: str | None = None) -> str:
    """libseccomp's readable listing of the filter."""
    return _export(arch or native_arch(), "pfc").decode()


def available() -> bool:
    try:
        filter_bytes()
    except SeccompUnavailable:
        return False
    return True


def open_filter_fd() -> int:
    """A sealed memfd holding the filter, read from its start: one per run (bwrap reads it to
    the end). It is close-on-exec: hand it to bwrap with ``pass_fds``, close it after."""
    data = filter_bytes()
    fd = os.memfd_create("robotide-seccomp", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        seals = fcntl.F_SEAL_SEAL | fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_WRITE
        fcntl.fcntl(fd, fcntl.F_ADD_SEALS, seals)
        os.lseek(fd, 0, os.SEEK_SET)
    except BaseException:
        os.close(fd)
        raise
    return fd


def bwrap_args(fd: int) -> list[str]:
    return ["--seccomp", str(fd)]
