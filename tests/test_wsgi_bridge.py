"""robotide.wsgi_bridge: Django's WSGI handler under the ASGI server, one trip to a worker
thread per request; driven here as uvicorn drives it (ASGI messages in, messages out)."""

import asyncio
import threading

import pytest
from django.http import HttpResponse, StreamingHttpResponse

from robotide.wsgi_bridge import PREFETCH_BYTES, OneHopWSGI


def http_scope(method="POST", body_length=None) -> dict:
    headers = [(b"host", b"robot.local")]
    if body_length is not None:
        headers.append((b"content-length", str(body_length).encode()))
    return {
        "type": "http", "http_version": "1.1", "method": method, "scheme": "http",
        "path": "/x", "raw_path": b"/x", "query_string": b"", "root_path": "",
        "headers": headers, "client": ("127.0.0.1", 5000), "server": ("127.0.0.1", 8000),
    }  # fmt: skip


async def serve(app, scope, pieces: list[bytes]) -> tuple[list[dict], list[str]]:
    """Run one request; returns what was sent and, in order, what the server's loop saw:
    'receive' (a piece of body asked for) and 'send' (a message) events, each with the thread
    that caused it."""
    seen: list[str] = []
    sent: list[dict] = []
    queue = list(pieces)

    async def receive():
        seen.append("receive")
        await asyncio.sleep(0)
        if not queue:
            return {"type": "http.disconnect"}
        piece = queue.pop(0)
        return {"type": "http.request", "body": piece, "more_body": bool(queue)}

    async def send(message):
        seen.append("send")
        sent.append(message)

    await app(scope, receive, send)
    return sent, seen


def echo_app(environ, start_response):
    """A WSGI app as Django's handler is: it returns the HttpResponse itself."""
    length = int(environ.get("CONTENT_LENGTH") or 0)
    body = environ["wsgi.input"].read(length)
    response = HttpResponse(body, content_type="application/octet-stream")
    response["X-Thread"] = threading.current_thread().name
    start_response("201 Created", list(response.items()))
    return response


def test_a_small_body_is_read_first_and_the_response_sent_whole():
    body = b"x" * 1000
    pieces = [body[:300], body[300:700], body[700:]]  # as a slow client sends it
    sent, seen = asyncio.run(serve(OneHopWSGI(echo_app), http_scope(body_length=1000), pieces))
    # All of the body was read before anything was sent, and then two messages.
    assert seen == ["receive"] * 3 + ["send", "send"]
    start, whole = sent
    assert start["type"] == "http.response.start" and start["status"] == 201
    headers = dict(start["headers"])
    assert headers[b"x-thread"].startswith(b"WSGI")  # the app ran in a worker thread
    assert whole == {"type": "http.response.body", "body": body}  # no more_body: the end


def test_a_large_body_is_read_from_the_thread_on_demand():
    size = PREFETCH_BYTES * 3
    pieces = [bytes([n % 251]) * (size // 6) for n in range(6)]
    sent, seen = asyncio.run(serve(OneHopWSGI(echo_app), http_scope(body_length=size), pieces))
    assert b"".join(m.get("body", b"") for m in sent[1:]) == b"".join(pieces)
    assert seen[0] == "receive" and seen.count("receive") == 6


def test_a_body_cut_short_by_a_disconnect_gives_what_came():
    sent, _ = asyncio.run(serve(OneHopWSGI(echo_app), http_scope(body_length=1000), [b"ab"]))
    assert sent[-1]["body"] == b"ab"


def test_a_request_without_a_body_is_not_read():
    sent, seen = asyncio.run(serve(OneHopWSGI(echo_app), http_scope("GET"), []))
    assert seen == ["send", "send"] and sent[1]["body"] == b""


def test_a_streamed_response_goes_chunk_by_chunk_with_its_end():
    """A download is never held whole: each chunk is sent as the app makes it."""
    made: list[int] = []

    def chunks():
        for n in range(5):
            made.append(n)
            yield bytes([65 + n]) * 10

    def app(environ, start_response):
        response = StreamingHttpResponse(chunks())
        start_response("200 OK", list(response.items()))
        return response

    sent, _ = asyncio.run(serve(OneHopWSGI(app), http_scope("GET"), []))
    bodies = [m for m in sent if m["type"] == "http.response.body"]
    assert [m["body"] for m in bodies] == [bytes([65 + n]) * 10 for n in range(5)] + [b""]
    assert all(m["more_body"] for m in bodies[:-1]) and not bodies[-1].get("more_body")


def test_an_app_that_raises_raises_to_the_server():
    """uvicorn answers 500 to an application that raises; Django's handler never does."""

    def app(environ, start_response):
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        asyncio.run(serve(OneHopWSGI(app), http_scope("GET"), []))
