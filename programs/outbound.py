"""Programs leaving this appliance: sent by e-mail, or pushed to another robotide.

Both are refused with ``OutboundError``: its message is for the user, its ``status`` the HTTP
status that fits.

    OutboundError
     ├── 403  sending by e-mail is turned off here (ROBOTIDE_EMAIL_PER_HOUR=0)
     ├── 422  not an e-mail address, not an http(s) URL, not a token
     ├── 429  too many this hour (per user: the appliance must not become a spam relay)
     ├── 502  the mail server or the other robotide refused, or the other cannot be reached
     ├── 503  the mail server cannot be reached
     └── 504  the other robotide did not answer in time

A push is robot to robot, as the paper's Bluetooth share: the program is POSTed to the other
appliance's ``/api/programs`` with a token of the account that gets it, and arrives there as
that account's program, with ``origin`` saying where it came from.
"""

import http.client
import json
import math
import re
import smtplib
import socket
import ssl
import time
import urllib.error
import urllib.request
from urllib.parse import urlsplit, urlunsplit

from django.conf import settings
from django.core.cache import cache
from django.core.exceptions import ValidationError
from django.core.mail import EmailMessage
from django.core.validators import EmailValidator

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


def _take_allowance(kind: str, user, per_hour: int, noun: str) -> str:
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
        raise OutboundError(
            f"You may send at most {per_hour} {noun} an hour: try again in {minutes} min.", 429
        )
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
        raise OutboundError(f"{one_line(to, 80)!r} is not an e-mail address.", 422) from None
    if settings.EMAIL_PER_HOUR <= 0:
        raise OutboundError("Sending programs by e-mail is turned off on this robotide.", 403)
    key = _take_allowance("mail", user, settings.EMAIL_PER_HOUR, "e-mails")
    message = EmailMessage(
        subject=one_line(f"{program.name}: a robot program from {user.get_username()}", 150),
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
        raise OutboundError(f"The mail server refused the mail: {_smtp_reason(exc)}.", 502) from exc
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
    written = "" if program.owner_id == user.pk else f", written by {program.owner.get_username()}"
    return (
        f"{sender} sent you the robot program {program.name!r} ({program.lang.label}{written})\n"
        f"from the robotide at {site}/\n\n"
        f"It is attached as {program.filename}.\n\n"
        "robotide is a web-based robot programming environment. If you did not expect this\n"
        "mail, you may ignore it: nothing else will come unless someone there sends it.\n"
    )


def _is_address(value: str) -> bool:
    try:
        EmailValidator()(value or "")
    except ValidationError:
        return False
    return True


def _mail_server_away(exc: Exception) -> str:
    where = f"{settings.EMAIL_HOST}:{settings.EMAIL_PORT}" if settings.EMAIL_HOST else "configured"
    why = exc.strerror if isinstance(exc, OSError) and exc.strerror else type(exc).__name__
    return f"Cannot send mail now: the mail server ({where}) cannot be reached ({why})."


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
            "Give an API token of the account there that should get the program"
            " (`robotide token USERNAME` on that robotide).",
            422,
        )
    # Counted whether it arrives or not: each push is a request to an address the user chose.
    _take_allowance("push", user, PUSHES_PER_HOUR, "pushes")
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
        status, answer, headers = _post(base, token, body)
        if status == 201 and isinstance(answer, dict):
            return {
                "url": base,
                "id": answer.get("id") if isinstance(answer.get("id"), int) else None,
                "name": str(answer.get("name", body["name"])),
                "owner": str(answer.get("owner", "")),
            }
        if status != 409:  # 409: the account has a program of that name
            raise OutboundError(_refusal(base, status, answer, headers), 502)
    raise OutboundError(
        f"The account at {base} already has programs named {program.name!r} to"
        f" {body['name']!r}: rename the program first.",
        502,
    )


def robotide_url(url: str) -> str:
    """``http://host:port`` (with a path prefix, if any), or 422."""
    url = (url or "").strip()
    problem = "Give the other robotide's address as http://HOST:PORT or https://HOST."
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
        raise OutboundError("Give the address without a user name: the token says who.", 422)
    return urlunsplit((parts.scheme.lower(), parts.netloc, parts.path.rstrip("/"), "", ""))


class _NoRedirects(urllib.request.HTTPRedirectHandler):
    # A redirect is reported, not followed: the token must not go on to another address.
    def redirect_request(self, req, fp, code, msg, headers, newurl):
        return None


# Directly, never through a proxy from the environment: the token goes to the address given.
_opener = urllib.request.build_opener(urllib.request.ProxyHandler({}), _NoRedirects())


def _post(base: str, token: str, body: dict):
    request = urllib.request.Request(
        base + "/api/programs",
        data=json.dumps(body).encode(),
        method="POST",
        headers={
            "Content-Type": "application/json",
            "Accept": "application/json",
            "Authorization": f"Bearer {token}",
            "User-Agent": "robotide-push",
        },
    )
    try:
        with _opener.open(request, timeout=PUSH_TIMEOUT) as response:
            return response.status, _read_json(response), response.headers
    except urllib.error.HTTPError as exc:
        with exc:
            return exc.code, _read_json(exc), exc.headers
    except TimeoutError as exc:
        raise OutboundError(_late(base), 504) from exc
    except urllib.error.URLError as exc:
        if isinstance(exc.reason, TimeoutError):
            raise OutboundError(_late(base), 504) from exc
        raise OutboundError(f"Cannot reach {base} ({_why(exc.reason)}).", 502) from exc
    except http.client.InvalidURL as exc:
        raise OutboundError(f"{base} is not an address to push to.", 422) from exc
    except (http.client.HTTPException, OSError) as exc:  # dropped mid-answer, or not HTTP
        raise OutboundError(f"Cannot reach {base} ({_why(exc)}).", 502) from exc


def _read_json(response):
    data = response.read(MAX_ANSWER_BYTES + 1)
    if len(data) > MAX_ANSWER_BYTES:
        return None
    try:
        return json.loads(data)
    except ValueError:
        return None


def _late(base: str) -> str:
    return f"The robotide at {base} did not answer within {PUSH_TIMEOUT:g} s."


def _why(reason) -> str:
    if isinstance(reason, ConnectionRefusedError):
        return "connection refused"
    if isinstance(reason, socket.gaierror):
        return "no such host"
    if isinstance(reason, ssl.SSLCertVerificationError):
        return f"its TLS certificate is not trusted: {reason.verify_message}"
    if isinstance(reason, OSError) and reason.strerror:
        return reason.strerror.lower()
    return one_line(str(reason) or type(reason).__name__, 200)


def _refusal(base: str, status: int, answer, headers) -> str:
    if status in (401, 403):
        return (
            f"The token was refused by {base}: make one there for the account that should get"
            " the program (`robotide token USERNAME`)."
        )
    if status == 413:
        return f"The program is too large for the robotide at {base}."
    if 300 <= status < 400:
        where = one_line(headers.get("Location", "") if headers else "", 200)
        return f"{base} redirects to {where or 'another address'}: give that address instead."
    detail = _detail(answer)
    if status == 404 or not detail:
        return f"{base} does not look like a robotide: it answered {status} to POST /api/programs."
    return f"{base} refused the program: {detail}"


def _detail(answer) -> str:
    """The remote's ``{"detail": ...}``: a message, or pydantic's list of errors."""
    detail = answer.get("detail") if isinstance(answer, dict) else None
    if isinstance(detail, list):
        messages = [str(e.get("msg", "")) for e in detail if isinstance(e, dict)]
        detail = "; ".join(m.removeprefix("Value error, ") for m in messages if m)
    return one_line(detail, 300) if isinstance(detail, str) else ""
