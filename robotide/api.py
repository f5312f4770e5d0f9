"""The REST API: /api/, JSON, OpenAPI at /api/openapi.json.

Authenticated by the session (with CSRF) or ``Authorization: Bearer <token>``.
"""

from django.core.exceptions import PermissionDenied
from django.http import Http404, JsonResponse
from django.utils.translation import gettext as _
from django.views import defaults
from ninja import NinjaAPI
from ninja.errors import AuthenticationError, HttpError, ValidationError
from ninja.security import HttpBearer, django_auth

from classroom.api import attempts_router, classes_router, exercises_router
from programs.api import programs_router, runs_router
from programs.shares_api import groups_router, shares_router
from robotide.models import ApiToken
from robotide.tokens_api import tokens_router
from robots.api import robots_router
from robots.bridges_api import bridges_router
from robots.bus import AgentUnavailable
from robots.gateway_api import gateway_router
from robots.runs import AgentUnreachable, RunRefused
from robots.sims_api import sims_router
from worlds.api import worlds_router


class BearerToken(HttpBearer):
    def authenticate(self, request, token):
        user = ApiToken.user_for(token)
        if user is not None:
            request.user = user
        return user


ERROR = {
    "type": "object",
    "properties": {"detail": {"type": "string"}},
    "required": ["detail"],
}
# Pydantic's validation errors come as a list: [{"type", "loc", "msg"}, ...].
VALIDATION_ERROR = {
    "type": "object",
    "properties": {"detail": {"anyOf": [{"type": "string"}, {"type": "array"}]}},
    "required": ["detail"],
}
ERROR_DESCRIPTIONS = {
    400: "Bad Request (the body is not JSON)",
    401: "Unauthorized",
    403: "Forbidden (staff only, or a session request without its CSRF token)",
    404: "Not Found",
    413: "Request too large",
    422: "Unprocessable Content (invalid parameters or body)",
}


class RobotideAPI(NinjaAPI):
    """NinjaAPI whose schema also documents the errors every operation can answer with."""

    def get_openapi_schema(self, **kwargs):
        schema = super().get_openapi_schema(**kwargs)
        for operations in schema["paths"].values():
            for method, operation in operations.items():
                statuses = set()
                if operation.get("security"):
                    statuses.add(401)
                    if method != "get":
                        statuses.add(403)
                if any(p["in"] == "path" for p in operation.get("parameters", [])):
                    statuses.add(404)
                if operation.get("parameters") or "requestBody" in operation:
                    statuses.add(422)
                if "requestBody" in operation:
                    statuses.update((400, 413))
                responses = operation["responses"]
                # ninja keys its own statuses by number: one key per status, whatever its type.
                for key in [k for k in responses if isinstance(k, int)]:
                    responses[str(key)] = responses.pop(key)
                for status in sorted(statuses):
                    body = VALIDATION_ERROR if status == 422 else ERROR
                    responses.setdefault(
                        str(status),
                        {
                            "description": ERROR_DESCRIPTIONS[status],
                            "content": {"application/json": {"schema": body}},
                        },
                    )
        return schema


api = RobotideAPI(
    title="robotide",
    version="1",
    description="Programs, runs and robots of a robotide appliance.",
    auth=[BearerToken(), django_auth],
    urls_namespace="api",
)
api.add_router("/programs", programs_router)
api.add_router("/runs", runs_router)
api.add_router("/robots", robots_router)
api.add_router("/robots", gateway_router)
api.add_router("/robots", bridges_router)
api.add_router("/programs", shares_router)
api.add_router("/groups", groups_router)
api.add_router("/tokens", tokens_router)
api.add_router("/sims", sims_router)
api.add_router("/worlds", worlds_router)
api.add_router("/classes", classes_router)
api.add_router("/exercises", exercises_router)
api.add_router("/attempts", attempts_router)


@api.exception_handler(Http404)
def not_found(request, exc):
    return api.create_response(request, {"detail": str(exc) or _("Not found.")}, status=404)


@api.exception_handler(PermissionDenied)
def forbidden(request, exc):
    return api.create_response(request, {"detail": str(exc) or _("Not allowed.")}, status=403)


@api.exception_handler(AuthenticationError)
def unauthorized(request, exc):
    detail = _("Authentication required: sign in or send Authorization: Bearer <token>.")
    return api.create_response(request, {"detail": detail}, status=401)


@api.exception_handler(ValidationError)
def invalid(request, exc):
    """Pydantic's list of errors, each message as our validators wrote it: in the reader's
    language, without pydantic's English "Value error, " before it."""
    errors = [
        {**error, "msg": error["msg"].removeprefix("Value error, ")}
        if error.get("type") == "value_error" and isinstance(error.get("msg"), str)
        else error
        for error in exc.errors
    ]
    return api.create_response(request, {"detail": errors}, status=422)


@api.exception_handler(AgentUnavailable)
@api.exception_handler(AgentUnreachable)
def agent_unavailable(request, exc):
    return api.create_response(request, {"detail": str(exc)}, status=503)


@api.exception_handler(RunRefused)
def run_refused(request, exc):
    return api.create_response(request, {"detail": str(exc)}, status=409)


__all__ = ["api", "HttpError", "page_not_found"]


def page_not_found(request, exception):
    """Django's 404 page, or JSON under /api/ (a path no route matches, e.g. /api/runs/x)."""
    if request.path.startswith("/api/"):
        return JsonResponse({"detail": _("Not found.")}, status=404)
    return defaults.page_not_found(request, exception)
