"""A pass to a run's live websocket, given with what has just shown the viewer the run.

The run's page and the API's answer about a run (a start's, above all) checked the viewer's
access a moment before. The websocket the viewer opens next may send the log on that check
instead of reading the session, the user and the run again first: three queries on the thread
all database work waits for, while a start writes its state, and a start's first line waited
for them.

A pass is signed with the server's secret and names the run and what its lines are rendered
with (language, program name: a pass is read without the database). It holds only for the
browser session it was given to (a digest of the session key: the URL may end up in a log, the
key must not) and for ACCESS_STANDS_SECONDS, the time any websocket's access read stands: the
consumer reads access in full once that has passed, before it sends anything more, and closes
if it is gone.
"""

import time
from dataclasses import dataclass
from urllib.parse import urlencode

from django.contrib.auth import SESSION_KEY
from django.core import signing
from django.utils.crypto import constant_time_compare, salted_hmac

from programs.access import ACCESS_STANDS_SECONDS

SALT = "robotide.programs.watch_pass"


@dataclass(frozen=True)
class WatchPass:
    run_id: int
    language: str
    program_name: str
    age: float  # seconds since the access it stands for was read


def live_path(run, request, shown_up_to: int | None = None) -> str:
    """The path of ``run``'s websocket for whoever ``request`` answers, with their pass and
    the log offset their page holds."""
    query = {"from": shown_up_to} if shown_up_to is not None else {}
    if (given := give_for(request, run)) is not None:
        query["pass"] = given
    return f"/ws/runs/{run.pk}/" + (f"?{urlencode(query)}" if query else "")


def give_for(request, run) -> str | None:
    """A pass for the session that made ``request``, if it is the session of the user the
    request is answered for: not a token's (a token's caller may send another's cookie)."""
    session, user = getattr(request, "session", None), getattr(request, "user", None)
    if session is None or user is None or not user.is_authenticated:
        return None
    if session.get(SESSION_KEY) != str(user.pk):
        return None
    return give(run, session.session_key)


def give(run, session_key: str | None) -> str | None:
    """A pass to ``run``'s websocket for this session; None without one (a token's caller)."""
    if not session_key:
        return None
    facts = [run.pk, run.language, run.program_name, _of_session(session_key), time.time()]
    return signing.dumps(facts, salt=SALT, compress=False)


def read(text: str | None, run_id: int, session_key: str | None) -> WatchPass | None:
    """The pass, if it is ours, for this run and this session, and still stands."""
    if not text or not session_key:
        return None
    try:
        pk, language, program_name, session, issued = signing.loads(text, salt=SALT)
        age = time.time() - float(issued)
    except (signing.BadSignature, ValueError, TypeError):
        return None
    if pk != run_id or not constant_time_compare(session, _of_session(session_key)):
        return None
    if not 0 <= age < ACCESS_STANDS_SECONDS:
        return None
    return WatchPass(pk, language, program_name, age)


def _of_session(session_key: str) -> str:
    return salted_hmac(SALT, session_key).hexdigest()
