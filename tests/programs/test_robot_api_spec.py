"""The one description of the Robot API (programs/robot_api_spec.py) against what it
describes: every form, in every language, is run by the language's real interpreter with its
real client against a real Robot API server, which records what each call sent; and every
method that server dispatches is described."""

import asyncio
import base64
import json
import re

import pytest

from programs.languages import LANGUAGES
from programs.robot_api_spec import CALLS, CLIENTS, PLACEHOLDER, by_language, call_named
from robots.rpc import ROBOT_ERROR, RpcError
from runbox import launcher
from tests.robot_api_server import admit

TOKEN = "spec-token"
NO_MORE = "no more values in this test"

# What the recording server answers, shaped as the robot answers (the shell command reads
# some of these: a snapshot's jpeg, a barcode's text, what was heard).
ANSWERS = {
    "drive": {"linear": 0.2, "angular": 0.5},
    "stop": None,
    "sensors": {"heading": 12.5, "range": 2.0},
    "sensor": 12.5,
    "capabilities": {"kind": "sim"},
    "show": None,
    "publish": 1,
    "subscribe": None,
    "receive": 0.3,
    "memory_set": None,
    "memory_get": 3,
    "say": {"spoken": True, "seconds": 0.4},
    "snapshot": {"jpeg": base64.b64encode(b"\xff\xd8\xff\xd9").decode(), "width": 1, "height": 1},
    "scan_barcode": [{"text": "home", "format": "QRCode", "position": []}],
    "listen": {"text": "move", "words": ["move"]},
}


# -- the description itself ------------------------------------------------------------------


def test_every_call_has_a_form_or_says_why_not_in_every_language():
    for call in CALLS:
        for language in CLIENTS:
            assert (language in call.forms) != (language in call.absent), (call.name, language)
        assert call.summary.endswith(".") and "\n" not in call.summary, call.name
        assert call.doc and call.returns, call.name


def test_the_languages_are_the_editors():
    assert set(CLIENTS) <= set(LANGUAGES)


def test_forms_name_only_their_calls_parameters_in_the_order_they_are_sent():
    for call in CALLS:
        sent = [p.name for p in call.sent_params()]
        for language, form in call.forms.items():
            named = PLACEHOLDER.findall(form)
            assert set(named) <= {p.name for p in call.params}, (call.name, language)
            in_order = [name for name in named if name in sent]
            assert in_order == sent[: len(in_order)], (call.name, language)
            for p in call.sent_params():
                if p.default is None:  # a parameter that must be given is in every form
                    assert p.name in named, (call.name, language, p.name)


def test_each_language_names_a_call_by_its_clients_word():
    python = {c["name"]: c for c in by_language("python")["calls"]}
    assert python["drive"]["word"] == "drive"
    assert python["drive"]["signature"] == "bot.drive(linear, angular)"
    assert python["drive"]["insert"] == "drive(|)"
    assert python["stop"]["insert"] == "stop()|"
    assert python["connect"]["word"] == "Robot"
    assert python["drive"]["example"] == "bot.drive(0.2, 0.5)"
    perl = {c["name"]: c for c in by_language("perl")["calls"]}
    assert perl["drive"]["signature"] == "$bot->drive($linear, $angular)"
    assert perl["stop"]["insert"] == "stop|"
    shell = {c["name"]: c for c in by_language("shell")["calls"]}
    assert shell["drive"]["signature"] == "robot drive LINEAR [ANGULAR]"
    assert shell["memory_get"]["word"] == "memory get"
    assert shell["memory_get"]["insert"] == "memory get |"
    assert shell["listen"]["example"] == "robot listen 3 --wav heard.wav --words move,stop"
    assert "connect" not in shell and "close" not in shell
    tcl = {c["name"]: c for c in by_language("tcl")["calls"]}
    assert tcl["receive"]["signature"] == "robot::receive topic ?timeout?"
    assert tcl["listen"]["example"] == "robot::listen 3 heard.wav {move stop}"
    lua = {c["name"]: c for c in by_language("lua")["calls"]}
    assert lua["listen"]["example"] == "bot:listen(3, 'heard.wav', {'move', 'stop'})"
    assert lua["drive"]["params"] == [
        {"name": "linear", "unit": "m/s", "meaning": "forward speed; negative backs up",
         "default": None},
        {"name": "angular", "unit": "rad/s", "meaning": "turn rate, counter-clockwise",
         "default": "0"},
    ]  # fmt: skip


def test_every_language_is_json_and_its_patterns_are_regular_expressions():
    for language in CLIENTS:
        help_ = json.loads(json.dumps(by_language(language)))
        re.compile(help_["objects"])
        re.compile(help_["connects"])
        calls = help_["calls"]
        assert len(calls) == len({(c["word"], c["signature"]) for c in calls}), language
        for call in help_["calls"]:
            assert call["insert"].count("|") == 1, (language, call["name"])
    with pytest.raises(KeyError):
        by_language("cobol")


# -- the description against the server and the clients ----------------------------------------


async def test_every_method_the_server_dispatches_is_described(agent):
    described = {call.rpc for call in CALLS if call.rpc}
    assert described == {"auth", *agent.api.methods}
    assert set(ANSWERS) == described - {"auth"}


@pytest.fixture
async def recorded(agent):
    """The agent's server, recording each call after auth and answering from ANSWERS; a
    connection's second receive fails (the shell's subscribe would print values for ever)."""
    admit(agent, TOKEN, 7)
    calls: list[tuple[str, list]] = []
    receives: dict[int, int] = {}
    real = agent.server.handler

    async def handler(session, method, params):
        if method == "auth" or session.run is None:
            result = await real(session, method, params)
            calls.append((method, params))
            return result
        calls.append((method, params))
        if method not in ANSWERS:
            return await real(session, method, params)
        if method == "receive":
            receives[id(session)] = receives.get(id(session), 0) + 1
            if receives[id(session)] > 1:
                raise RpcError(ROBOT_ERROR, NO_MORE)
        return ANSWERS[method]

    agent.server.handler = handler
    return calls


def program(language: str) -> str:
    """Every call's example, in the order described (connect first, close last)."""
    client = CLIENTS[language]
    lines = [client.example(call) for call in CALLS if language in call.forms]
    if language == "perl":
        return "use strict;\nuse warnings;\nuse Robot;\n" + "".join(f"{s};\n" for s in lines)
    if language == "javascript":
        body = "".join(f"  {s};\n" for s in lines)
        return (
            f"{client.setup}\n(async () => {{\n{body}}})()"
            ".catch((e) => { console.error(e.message); process.exit(1); });\n"
        )
    return "".join(f"{s}\n" for s in [client.setup, *lines] if s)


def sent_as_described(call, language: str, params: list) -> bool:
    """Whether the params the robot got carry each parameter the form names, at its place."""
    named = PLACEHOLDER.findall(call.forms[language])
    for index, p in enumerate(call.sent_params()):
        if p.name not in named:
            continue
        if index >= len(params) or params[index] != p.example:
            return False
    return True


@pytest.mark.parametrize("language", list(CLIENTS))
async def test_every_form_works_in_its_language(recorded, agent, tmp_path, language):
    source = program(language)
    file = tmp_path / f"program{LANGUAGES[language].extension}"
    file.write_text(source)
    env = launcher.environment(
        LANGUAGES[language],
        tmp_path,
        {"ROBOT_API": agent.server.url, "ROBOT_API_TCP": agent.api_address, "ROBOT_TOKEN": TOKEN},
    )
    process = await asyncio.create_subprocess_exec(
        *LANGUAGES[language].command(str(file)),
        env=env,
        cwd=tmp_path,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        out, err = await asyncio.wait_for(process.communicate(), 60)
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    err = err.decode()
    context = f"{language} program:\n{source}\nstderr: {err}\ncalls: {recorded}"
    if language == "shell":  # each line its own command; only subscribe's end is an error
        assert all(NO_MORE in line for line in err.splitlines()), context
        assert (tmp_path / "frame.jpg").read_bytes() == b"\xff\xd8\xff\xd9"
    else:
        assert process.returncode == 0, context
    assert ("auth", [TOKEN]) in recorded, context
    for call in CALLS:
        if language not in call.forms or call.rpc in (None, "auth"):
            continue
        assert any(
            method == call.rpc and sent_as_described(call, language, params)
            for method, params in recorded
        ), f"{call.name}: {context}"


def test_the_examples_say_what_the_clients_headers_say():
    # A few of the clients' own usage lines, word for word.
    assert CLIENTS["python"].example(call_named("show")) == "bot.show('speed', 0.2)"
    assert CLIENTS["perl"].example(call_named("stop")) == "$bot->stop"
    assert CLIENTS["ruby"].example(call_named("drive")) == "bot.drive(0.2, 0.5)"
    assert CLIENTS["tcl"].example(call_named("drive")) == "robot::drive 0.2 0.5"
