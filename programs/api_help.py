"""Help on the Robot API, made from its one description (programs/robot_api_spec.py): as JSON
for the editor's completion and hover help (robotide/static/robotide/api_help.js), and as the
help page, one section per call with each language's form."""

from django.contrib.auth.decorators import login_required
from django.http import Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import render
from django.urls import reverse
from django.utils.translation import gettext as _

from programs.robot_api_spec import CALLS, CLIENTS, by_language
from programs.robot_api_words import call_shown, client_shown, help_shown


@login_required
def robot_api_help(request: HttpRequest, language: str) -> JsonResponse:
    """One language's calls: signature, parameters with units, summary, doc, example."""
    if language not in CLIENTS:
        raise Http404(_("no Robot API client for %(language)s") % {"language": repr(language)})
    help_ = help_shown(by_language(language))  # its words in the reader's language
    page = reverse("robot-api-page")
    for call in help_["calls"]:
        call["page"] = f"{page}#{call['name']}"
    return JsonResponse(help_)


@login_required
def robot_api_page(request: HttpRequest) -> HttpResponse:
    clients = [client_shown(client) for client in CLIENTS.values()]
    groups: dict[str, list[dict]] = {}
    for call in map(call_shown, CALLS):  # its words in the reader's language
        rows = []
        for client in clients:
            form = call.forms.get(client.language)
            if form is None:
                rows.append({"client": client, "absent": call.absent[client.language]})
                continue
            rows.append(
                {
                    "client": client,
                    "signature": client.display(form),
                    "example": client.example(call),
                    "note": call.notes.get(client.language, ""),
                }
            )
        groups.setdefault(call.group, []).append({"call": call, "rows": rows})
    return render(
        request,
        "programs/robot_api.html",
        {"groups": groups, "clients": clients, "connect": _connect_examples(clients)},
    )


def _connect_examples(clients) -> list[dict]:
    """Per language, the first lines of a program that drives: setup, connect, one call."""
    connect = next(call for call in CALLS if call.rpc == "auth")
    drive = next(call for call in CALLS if call.name == "drive")
    examples = []
    for client in clients:
        lines = [client.setup] if client.setup else []
        if client.language in connect.forms:
            lines.append(client.example(connect))
        lines.append(client.example(drive))
        examples.append({"client": client, "code": "\n".join(lines)})
    return examples
