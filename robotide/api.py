"""The REST API: /api/, JSON, OpenAPI at /api/openapi.json.

Authenticated by the session (with CSRF) or ``Authorization: Bearer <token>``.
"""

from django.http import Http404
from ninja import NinjaAPI
from ninja.errors import AuthenticationError, HttpError
from ninja.security import HttpBearer, django_auth

from programs.api import programs_router, runs_router
from programs.models import RunRefused
from robotide.models import ApiToken
from robots.api import robots_router
from robots.bus import AgentUnavailable


class BearerToken(HttpBearer):
    def authenticate(self, request, token):
        user = ApiToken.user_for(token)
        if user is not None:
            request.user = user
        return user


api = NinjaAPI(
    title="robotide",
    version="1",
    description="Programs, runs and robots of a robotide appliance.",
    auth=[BearerToken(), django_auth],
    urls_namespace="api",
)
api.add_router("/programs", programs_router)
api.add_router("/runs", runs_router)
api.add_router("/robots", robots_router)


@api.exception_handler(Http404)
def not_found(request, exc):
    return api.create_response(request, {"detail": str(exc) or "Not found."}, status=404)


@api.exception_handler(AuthenticationError)
def unauthorized(request, exc):
    detail = "Authentication required: sign in or send Authorization: Bearer <token>."
    return api.create_response(request, {"detail": detail}, status=401)


@api.exception_handler(AgentUnavailable)
def agent_unavailable(request, exc):
    return api.create_response(request, {"detail": str(exc)}, status=503)


@api.exception_handler(RunRefused)
def run_refused(request, exc):
    return api.create_response(request, {"detail": str(exc)}, status=409)


__all__ = ["api", "HttpError"]
