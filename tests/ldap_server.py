"""A real OpenLDAP slapd for the directory sign-in tests (tests/test_ldap.py, and the browser's
tests/browser/test_ldap_signin.py): started on a free port with a temporary config and database
holding a student, a teacher and a staff member and their groups."""

import shutil
import socket
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests.conftest import in_ci

SLAPD = shutil.which("slapd") or "/usr/sbin/slapd"
SCHEMAS = Path("/etc/ldap/schema")
SUFFIX = "dc=uni,dc=test"
ADMIN_DN, ADMIN_PASSWORD = f"cn=admin,{SUFFIX}", "directory-secret"
PEOPLE, GROUPS = f"ou=people,{SUFFIX}", f"ou=groups,{SUFFIX}"


def person(uid: str, given: str, surname: str, password: str) -> str:
    return f"""dn: uid={uid},{PEOPLE}
objectClass: inetOrgPerson
uid: {uid}
cn: {given} {surname}
givenName: {given}
sn: {surname}
mail: {uid}@uni.test
userPassword: {password}
"""


def group(cn: str, *members: str) -> str:
    lines = "".join(f"member: uid={m},{PEOPLE}\n" for m in members)
    return f"dn: cn={cn},{GROUPS}\nobjectClass: groupOfNames\ncn: {cn}\n{lines}"


DIRECTORY = "\n".join(
    [
        f"dn: {SUFFIX}\nobjectClass: dcObject\nobjectClass: organization\ndc: uni\no: Uni\n",
        f"dn: {PEOPLE}\nobjectClass: organizationalUnit\nou: people\n",
        f"dn: {GROUPS}\nobjectClass: organizationalUnit\nou: groups\n",
        person("stu", "Sam", "Student", "stu-pass-1"),
        person("tea", "Tess", "Teacher", "tea-pass-1"),
        person("sta", "Stan", "Staff", "sta-pass-1"),
        group("class-robotics1", "stu", "tea"),
        group("chess-club", "stu"),  # not a class
        group("teachers", "tea"),
        group("staff", "sta"),
    ]
)

SLAPD_CONF = """\
include {schemas}/core.schema
include {schemas}/cosine.schema
include {schemas}/inetorgperson.schema
include {schemas}/nis.schema
modulepath /usr/lib/ldap
moduleload back_mdb
pidfile {dir}/slapd.pid
database mdb
maxsize 16777216
suffix "{suffix}"
rootdn "{rootdn}"
rootpw {rootpw}
directory {dir}/db
access to attrs=userPassword by anonymous auth by * none
access to * by * read
"""


def ldap_env(uri: str) -> dict[str, str]:
    """The ROBOTIDE_LDAP_* that point robotide at this directory."""
    return {
        "ROBOTIDE_LDAP_URI": uri,
        "ROBOTIDE_LDAP_BIND_DN": ADMIN_DN,
        "ROBOTIDE_LDAP_BIND_PASSWORD": ADMIN_PASSWORD,
        "ROBOTIDE_LDAP_USER_BASE": PEOPLE,
        "ROBOTIDE_LDAP_USER_FILTER": "(uid=%(user)s)",
        "ROBOTIDE_LDAP_GROUP_BASE": GROUPS,
        "ROBOTIDE_LDAP_CLASS_FILTER": "(cn=class-*)",
        "ROBOTIDE_LDAP_TEACHER_FILTER": "(cn=teachers)",
        "ROBOTIDE_LDAP_STAFF_GROUP": f"cn=staff,{GROUPS}",
    }


def add_entries(conn, ldif: str) -> None:
    import ldap.modlist

    for entry in ldif.strip().split("\n\n"):
        lines = [line.split(": ", 1) for line in entry.strip().splitlines()]
        attrs: dict[str, list[bytes]] = {}
        for name, value in lines[1:]:
            attrs.setdefault(name, []).append(value.encode())
        conn.add_s(lines[0][1], ldap.modlist.addModlist(attrs))


@contextmanager
def as_directory_admin(uri: str):
    """An LDAP connection bound as the directory's admin, to change entries under a test."""
    import ldap

    conn = ldap.initialize(uri)
    conn.simple_bind_s(ADMIN_DN, ADMIN_PASSWORD)
    try:
        yield conn
    finally:
        conn.unbind_s()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _unavailable(why: str):
    if in_ci():
        pytest.fail(f"OpenLDAP's slapd is needed in CI: {why}")
    pytest.skip(why)


@contextmanager
def running_slapd(where: Path):
    """A running slapd in `where` holding DIRECTORY: its URI. Skips (fails in CI) without one."""
    if not Path(SLAPD).exists() or not (SCHEMAS / "inetorgperson.schema").exists():
        _unavailable("slapd is not installed (Debian: slapd ldap-utils)")
    import ldap

    (where / "db").mkdir()
    conf = where / "slapd.conf"
    conf.write_text(
        SLAPD_CONF.format(
            schemas=SCHEMAS, dir=where, suffix=SUFFIX, rootdn=ADMIN_DN, rootpw=ADMIN_PASSWORD
        )
    )
    uri = f"ldap://127.0.0.1:{_free_port()}"
    # -d keeps it in the foreground, our child, ended here.
    log = open(where / "slapd.log", "w")  # noqa: SIM115
    server = subprocess.Popen(
        [SLAPD, "-f", str(conf), "-h", uri + "/", "-d", "0"], stdout=log, stderr=log
    )
    try:
        deadline = time.monotonic() + 15
        while True:
            try:
                conn = ldap.initialize(uri)
                conn.simple_bind_s(ADMIN_DN, ADMIN_PASSWORD)
                break
            except ldap.LDAPError:
                if server.poll() is not None or time.monotonic() > deadline:
                    _unavailable(f"slapd did not start: {(where / 'slapd.log').read_text()}")
                time.sleep(0.1)
        add_entries(conn, DIRECTORY)
        conn.unbind_s()
        yield uri
    finally:
        server.terminate()
        server.wait(10)
        log.close()
