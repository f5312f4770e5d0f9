"""Programs leaving this appliance: sent by e-mail, or pushed to another robotide.

Both are refused with ``OutboundError``: its message is for the user, its ``status`` the HTTP
status that fits.

    OutboundError
     ├── 403  sending by e-mail is turned off here (ROBOTIDE_EMAIL_PER_HOUR=0), or a push to an
     │        address that is not public and not in ROBOTIDE_PUSH_ALLOW (refused before connecting)
     ├── 422  not an e-mail address, not an http(s) URL, not a token
     ├── 429  too many this hour (per user: the appliance must not become a spam relay)
     ├── 502  the mail server or the other robotide refused, the other is not reachable, or it
     │        is not a robotide
     ├── 503  the mail server cannot be reached
     └── 504  the other robotide is not reachable: no answer in time

A push is robot to robot, as the paper's Bluetooth share: the program is POSTed to the other
appliance's ``/api/programs`` with a token of the account that gets it, and arrives there as
that account's program, with ``origin`` saying where it came from.

A push goes only to the addresses its host name had when checked: public ones, or a lab's own
robotides listed in ROBOTIDE_PUSH_ALLOW. Its errors say "not reachable" or "not a robotide" and
never what answered, so it cannot probe the services of the lab's network.
"""

import functools
import http.client
import ipaddress
import json
import math
import re
import smtplib
import socket
import ssl
import time
from urllib.parse import quote, urlsplit, urlunsplit

from django.conf import settings
from django.core.cache import cache
from django.core.exceptions import ValidationError
from django.core.mail import EmailMessage
from django.core.validators import EmailValidator
from django.utils.translation import gettext as _

from programs.models import Program

PUSH_TIMEOUT = 10  # seconds, to connect and to each read
PUSHES_PER_HOUR = 60
NAME_TRIES = 10  # "name", "name (2)" ... "name (10)" on the other robotide
MAX_URL, MAX_TOKEN = 2000, 500
MAX_ANSWER_BYTES = 4 * 1024 * 1024  # the other's answer echoes the source (≤ 512 KB, escaped)
MAX_NAME = Program._meta.get_field("name").max_length
MAX_ORIGIN = Program._meta.get_field("origin").max_length
CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


class OutboundError(Exception):
    def __init__(self, message: str, status: int):
        super().__init__(message)
        self.status = status


def site_of(request) -> str:
    """This robotide's address as the request reached it, e.g. ``http://lab-robot:8000``."""
    return request.build_absolute_uri("/").rstrip("/")


def one_line(text: str, limit: int = MAX_ORIGIN) -> str:
    """Text for a single-line field or header: no control characters, at most ``limit``."""
    return " ".join(CONTROL.sub(" ", text).split())[:limit]


def origin_text(site: str, user) -> str:
    return one_line(f"pushed from {site} by {user.get_username()}")


# -- Rate limits ----------------------------------------------------------------------------------


def _take_allowance(kind: str, user, per_hour: int, refusal: str) -> str:
    """Counts one more of ``kind`` for ``user`` in this clock hour, or refuses (429).

    Counters live in the cache: per process in embedded mode, shared through Redis in fleet mode.
    """
    window = int(time.time() // 3600)
    key = f"robotide:outbound:{kind}:{user.pk}:{window}"
    cache.add(key, 0, timeout=3600 + 60)
    try:
        count = cache.incr(key)
    except ValueError:  # expired between add and incr
        cache.set(key, 1, timeout=3600 + 60)
        count = 1
    if count > per_hour:
        minutes = math.ceil(((window + 1) * 3600 - time.time()) / 60)
        raise OutboundError(refusal % {"count": per_hour, "minutes": minutes}, 429)
    return key


def _give_back(key: str) -> None:
    try:
        cache.decr(key)
    except ValueError:  # the hour is over already
        pass


# -- E-mail ---------------------------------------------------------------------------------------


def email_program(program: Program, to: str, *, user, site: str) -> str:
    """Mails ``program`` with its source attached to one address; returns the address."""
    to = (to or "").strip()
    try:
        EmailValidator()(to)
    except ValidationError:
        raise OutboundError(
            _("%(to)s is not an e-mail address.") % {"to": repr(one_line(to, 80))}, 422
        ) from None
    if settings.EMAIL_PER_HOUR <= 0:
        raise OutboundError(_("Sending programs by e-mail is turned off on this robotide."), 403)
    refusal = _("You may send at most %(count)s e-mails an hour: try again in %(minutes)s min.")
    key = _take_allowance("mail", user, settings.EMAIL_PER_HOUR, refusal)
    message = EmailMessage(
        subject=one_line(
            _("%(name)s: a robot program from %(sender)s")
            % {"name": program.name, "sender": user.get_username()},
            150,
        ),
        body=_mail_body(program, user, site),
        to=[to],
        reply_to=[user.email] if _is_address(user.email) else None,
    )
    message.attach(program.filename, program.source, "text/plain")
    try:
        message.send()
    except (smtplib.SMTPServerDisconnected, smtplib.SMTPConnectError) as exc:
        _give_back(key)
        raise OutboundError(_mail_server_away(exc), 503) from exc
    except smtplib.SMTPException as exc:  # before OSError: it is one
        _give_back(key)
        raise OutboundError(
            _("The mail server refused the mail: %(why)s.") % {"why": _smtp_reason(exc)}, 502
        ) from exc
    except OSError as exc:  # refused, no such host, timed out
        _give_back(key)
        raise OutboundError(_mail_server_away(exc), 503) from exc
    return to


def _mail_body(program: Program, user, site: str) -> str:
    sender = user.get_username()
    if user.get_full_name():
        sender = f"{user.get_full_name()} ({sender})"
    if _is_address(user.email):
        sender += f" <{user.email}>"
    about = {"sender": sender, "name": repr(program.name), "language": program.lang.label}
    about.update(site=site, file=program.filename, author=program.owner.get_username())
    if program.owner_id == user.pk:
        said = _("%(sender)s sent you the robot program %(name)s (%(language)s)\n")
    else:
        said = _(
            "%(sender)s sent you the robot program %(name)s (%(language)s, written by %(author)s)\n"
        )
    return (
        said
        + _(
            "from the robotide at %(site)s/\n\n"
            "It is attached as %(file)s.\n\n"
            "robotide is a web-based robot programming environment. If you did not expect this\n"
            "mail, you may ignore it: nothing else will come unless someone there sends it.\n"
        )
    ) % about


def _is_address(value: str) -> bool:
    try:
        EmailValidator()(value or "")
    except ValidationError:
        return False
    return True


def _mail_server_away(exc: Exception) -> str:
    why = exc.strerror if isinstance(exc, OSError) and exc.strerror else type(exc).__name__
    if not settings.EMAIL_HOST:
        return _(
            "Cannot send mail now: the configured mail server cannot be reached (%(why)s)."
        ) % {"why": why}
    where = f"{settings.EMAIL_HOST}:{settings.EMAIL_PORT}"
    return _("Cannot send mail now: the mail server (%(where)s) cannot be reached (%(why)s).") % {
        "where": where,
        "why": why,
    }


def _smtp_reason(exc: smtplib.SMTPException) -> str:
    if isinstance(exc, smtplib.SMTPRecipientsRefused) and exc.recipients:
        code, text = next(iter(exc.recipients.values()))
    else:
        code, text = getattr(exc, "smtp_code", None), getattr(exc, "smtp_error", None)
    if code is None:
        return one_line(str(exc) or type(exc).__name__, 200)
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    return one_line(f"{code} {text}", 200)


# -- Push to another robotide ---------------------------------------------------------------------


def push_program(program: Program, url: str, token: str, *, user, site: str) -> dict:
    """POSTs ``program`` to the robotide at ``url`` as the account ``token`` belongs to there.

    A name it has already gets " (2)", " (3)"... Returns where it arrived: ``url``, ``id``,
    ``name`` and ``owner`` there.
    """
    base = robotide_url(url)
    token = (token or "").strip()
    if not token or len(token) > MAX_TOKEN or not token.isascii() or not token.isprintable():
        raise OutboundError(
            _(
                "Give an API token of the account there that should get the program"
                " (`robotide token USERNAME` on that robotide)."
            ),
            422,
        )
    # Counted whether it arrives or not: each push is a request to an address the user chose,
    # and a refused one still looked up a name the user chose.
    refusal = _("You may send at most %(count)s pushes an hour: try again in %(minutes)s min.")
    _take_allowance("push", user, PUSHES_PER_HOUR, refusal)
    addresses = checked_addresses(base)
    body = {
        "name": program.name,
        "language": program.language,
        "source": program.source,
        "origin": origin_text(site, user),
    }
    stem = program.name[: MAX_NAME - 8]  # room for " (10)"
    for n in range(1, NAME_TRIES + 1):
        if n > 1:
            body["name"] = f"{stem} ({n})"
        status, answer = _post(base, addresses, token, body)
        if status == 201 and _is_program(answer):
            return {
                "url": base,
                "id": answer["id"],
                "name": answer["name"],
                "owner": answer["owner"],
            }
        if status != 409 or not _is_error(answer):  # 409: the account has a program of that name
            raise OutboundError(_refusal(base, status, answer), 502)
    raise OutboundError(
        _(
            "The account at %(base)s already has programs named %(first)s to %(last)s:"
            " rename the program first."
        )
        % {"base": base, "first": repr(program.name), "last": repr(body["name"])},
        502,
    )


def robotide_url(url: str) -> str:
    """``http://host:port`` (with a path prefix, if any), or 422."""
    url = (url or "").strip()
    problem = _("Give the other robotide's address as http://HOST:PORT or https://HOST.")
    if not url or len(url) > MAX_URL or re.search(r"[\s\x00-\x1f\x7f]", url):
        raise OutboundError(problem, 422)
    try:
        parts = urlsplit(url)
        parts.port  # noqa: B018 - raises ValueError for a port that is no number
    except ValueError:
        raise OutboundError(problem, 422) from None
    if parts.scheme.lower() not in ("http", "https") or not parts.hostname:
        raise OutboundError(problem, 422)
    if parts.username is not None or parts.password is not None:
        raise OutboundError(_("Give the address without a user name: the token says who."), 422)
    return urlunsplit((parts.scheme.lower(), parts.netloc, parts.path.rstrip("/"), "", ""))


# -- Where a push may go --------------------------------------------------------------------------
# A push connects to an address the user chose, from inside the lab's network: without these
# checks it reaches this machine's databases and the cloud's metadata service (an SSRF), and
# its errors would tell which services listen where (a port scanner).

NAT64 = ipaddress.ip_network("64:ff9b::/96")  # the well-known prefix: the IPv4 is the last 32 bits


def checked_addresses(base: str) -> list[tuple]:
    """The addresses ``base``'s host has, looked up once; 403 if any is not one to push to.

    The push connects to these, so a second look-up cannot answer otherwise (DNS rebinding).
    """
    parts = urlsplit(base)
    try:
        found = socket.getaddrinfo(parts.hostname, _port(parts), type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:  # no such host
        raise OutboundError(_unreachable(base), 502) from exc
    # All of them: a name with one public and one private address is refused, not half-used.
    if not found or not all(_may_push_to(sockaddr[0]) for *_rest, sockaddr in found):
        raise OutboundError(
            _(
                "%(base)s is not an address to push to: pushes go to public addresses only, and"
                " to those ROBOTIDE_PUSH_ALLOW lists on this robotide."
            )
            % {"base": base},
            403,
        )
    return found


def _port(parts) -> int:
    return parts.port or (443 if parts.scheme == "https" else 80)


def _may_push_to(host: str) -> bool:
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return False
    ip = getattr(ip, "ipv4_mapped", None) or ip  # ::ffff:a.b.c.d is a.b.c.d
    return all(_allowed(each) or _public(each) for each in (ip, *_embedded(ip)))


def _embedded(ip) -> list:
    """The IPv4 addresses an IPv6 address leads to through a gateway (NAT64, 6to4, Teredo)."""
    if ip.version == 4:
        return []
    found = [ipaddress.IPv4Address(int(ip) & 0xFFFFFFFF)] if ip in NAT64 else []
    if ip.sixtofour:
        found.append(ip.sixtofour)
    if ip.teredo:
        found.extend(ip.teredo)
    return found


def _public(ip) -> bool:
    # is_global alone lets multicast through, and IPv6 site-local in Python 3.11.
    return ip.is_global and not (
        ip.is_loopback
        or ip.is_link_local
        or ip.is_private
        or ip.is_multicast
        or ip.is_reserved
        or ip.is_unspecified
        or getattr(ip, "is_site_local", False)
    )


def _allowed(ip) -> bool:
    """In ROBOTIDE_PUSH_ALLOW: a lab's own robotides on its LAN."""
    networks = (ipaddress.ip_network(each, strict=False) for each in settings.PUSH_ALLOW)
    return any(ip.version == net.version and ip in net for net in networks)


# -- The request ----------------------------------------------------------------------------------


class _Connection(http.client.HTTPConnection):
    """HTTP(S) to addresses checked already; the URL's host name goes in the Host header and,
    on https, in SNI and the certificate check."""

    def __init__(self, base: str, addresses: list[tuple]):
        parts = urlsplit(base)
        self.tls = parts.scheme == "https"
        self.default_port = 443 if self.tls else 80  # so Host gets no ":443"
        super().__init__(parts.hostname, _port(parts), timeout=PUSH_TIMEOUT)
        self.addresses = addresses

    def connect(self):
        sock = _connect(self.addresses, self.timeout)
        self.sock = _tls().wrap_socket(sock, server_hostname=self.host) if self.tls else sock


def _connect(addresses: list[tuple], timeout: float) -> socket.socket:
    """A socket connected to the first of ``addresses`` that takes it."""
    error = OSError("no address")
    for family, kind, proto, _name, sockaddr in addresses:
        sock = socket.socket(family, kind, proto)
        try:
            sock.settimeout(timeout)
            sock.connect(sockaddr)
            return sock
        except OSError as exc:
            sock.close()
            error = exc
    raise error


@functools.cache
def _tls() -> ssl.SSLContext:
    return ssl.create_default_context()


def _post(base: str, addresses: list[tuple], token: str, body: dict):
    """``(status, answer)``: the JSON object answered, or None if the answer is not one.

    Directly, never through a proxy from the environment: the token goes to the address given.
    A redirect is an answer like any other, never followed.
    """
    connection = _Connection(base, addresses)
    headers = {
        "Content-Type": "application/json",
        "Accept": "application/json",
        "Authorization": f"Bearer {token}",
        "User-Agent": "robotide-push",
    }
    path = quote(urlsplit(base).path, safe="/%!$&'()*+,;=:@~") + "/api/programs"
    try:
        connection.request("POST", path, json.dumps(body).encode(), headers)
        response = connection.getresponse()
        return response.status, _read_json(response)
    # Never what answered, or how it failed: that would make this a port scanner.
    except TimeoutError as exc:
        raise OutboundError(
            _("%(base)s is not reachable: no answer within %(seconds)s s.")
            % {"base": base, "seconds": f"{PUSH_TIMEOUT:g}"},
            504,
        ) from exc
    except http.client.RemoteDisconnected as exc:  # closed without a word: a ConnectionResetError
        raise OutboundError(_unreachable(base), 502) from exc
    except http.client.HTTPException as exc:  # an answer, not in HTTP
        raise OutboundError(_not_a_robotide(base), 502) from exc
    except OSError as exc:  # refused, reset, no route, TLS refused
        raise OutboundError(_unreachable(base), 502) from exc
    finally:
        connection.close()


def _read_json(response):
    if response.headers.get_content_type() != "application/json":
        return None
    data = response.read(MAX_ANSWER_BYTES + 1)
    if len(data) > MAX_ANSWER_BYTES:
        return None
    try:
        answer = json.loads(data)
    except ValueError:
        return None
    return answer if isinstance(answer, dict) else None


# -- What the answer means ------------------------------------------------------------------------
# Only what a robotide answers is told apart. Anything else is "not a robotide", whatever it
# was: the user learns nothing of the services at an address.


def _is_program(answer) -> bool:
    """A robotide's 201: the program as it is there."""
    return (
        isinstance(answer, dict)
        and type(answer.get("id")) is int
        and isinstance(answer.get("name"), str)
        and isinstance(answer.get("owner"), str)
    )


def _is_error(answer) -> bool:
    """A robotide's error: ``{"detail": ...}``, a message or pydantic's list of errors."""
    return isinstance(answer, dict) and isinstance(answer.get("detail"), str | list)


def _refusal(base: str, status: int, answer) -> str:
    if not _is_error(answer):
        return _not_a_robotide(base)
    if status in (401, 403):
        return _(
            "The token was refused by %(base)s: make one there for the account that should get"
            " the program (`robotide token USERNAME`)."
        ) % {"base": base}
    if status == 413:
        return _("The program is too large for the robotide at %(base)s.") % {"base": base}
    detail = _detail(answer)
    if status in (400, 422) and detail:
        return _("%(base)s refused the program: %(detail)s") % {"base": base, "detail": detail}
    return _not_a_robotide(base)


def _detail(answer) -> str:
    """The remote's ``{"detail": ...}``: a message, or pydantic's list of errors."""
    detail = answer.get("detail") if isinstance(answer, dict) else None
    if isinstance(detail, list):
        messages = [str(e.get("msg", "")) for e in detail if isinstance(e, dict)]
        detail = "; ".join(m.removeprefix("Value error, ") for m in messages if m)
    return one_line(detail, 300) if isinstance(detail, str) else ""


def _unreachable(base: str) -> str:
    if base.startswith("https:"):
        return _("%(base)s is not reachable, or its TLS certificate is not trusted here.") % {
            "base": base
        }
    return _("%(base)s is not reachable.") % {"base": base}


def _not_a_robotide(base: str) -> str:
    return _("%(base)s is not a robotide, or not its own address (redirects are not followed).") % {
        "base": base
    }
