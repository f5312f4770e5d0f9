"""A websocket's user and language, read in the consumer's own first trip to a worker thread.

channels' AuthMiddlewareStack reads the session's user in a trip of its own before the consumer
begins, and the consumer then makes another for what it shows (a run's page: the run and its
log). Here ``scope["user"]`` is read where it is first used, in that trip: a run's page gets
its first lines after one trip instead of two. On the event loop, before any trip, Django
refuses the query (SynchronousOnlyOperation): a consumer that needs the user there first awaits
``user_of(scope)``.

The account's language (robotide.language) is activated as the user is read; asgiref brings
what a worker thread activates back to the consumer's task, for the rest of the connection.
"""

from channels.auth import AuthMiddleware
from channels.db import database_sync_to_async
from channels.sessions import CookieMiddleware, SessionMiddleware
from django.contrib import auth
from django.utils import translation
from django.utils.functional import SimpleLazyObject

from robotide.language import account_language


class _SessionOnly:
    """What django.contrib.auth.get_user reads of a request: its session."""

    def __init__(self, session):
        self.session = session


def read_user(scope):
    """The session's user (as Django's get_user checks it for a page), and their language."""
    user = auth.get_user(_SessionOnly(scope["session"]))
    code = account_language(scope["session"], user)
    if code:
        translation.activate(code)
    return user


class LazyAuthMiddleware(AuthMiddleware):
    async def resolve_scope(self, scope):
        scope["user"] = SimpleLazyObject(lambda: read_user(scope))


def LazyAuthMiddlewareStack(inner):  # noqa: N802 (as channels' AuthMiddlewareStack)
    return CookieMiddleware(SessionMiddleware(LazyAuthMiddleware(inner)))


async def user_of(scope):
    """The websocket's user, read now if no trip has read it yet."""
    return await database_sync_to_async(_resolved)(scope)


def _resolved(scope):
    user = scope["user"]
    user.is_authenticated  # noqa: B018 (reads the lazy user here, in the worker thread)
    return user
