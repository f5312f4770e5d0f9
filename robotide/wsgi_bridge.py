"""Django's WSGI handler under the ASGI server, with one trip to a worker thread per request.

a2wsgi's responder crosses between the thread and the event loop for every piece of a
request: a read of the body, the response's start, each body chunk and its end, each waiting
for the loop. While a run starts, the loop is busy with its robot's agent, and those waits were
most of a start's HTTP response (a POST: five crossings). Here a small body is read on the loop
before the thread takes the request, and a response that is not streamed comes back with the
thread's result, sent at once. Streamed responses (downloads, exports) still go chunk by chunk,
with a2wsgi's back-pressure, so a large file is never held whole.
"""

import asyncio
import contextvars
import functools
import io

from a2wsgi.wsgi import Body, WSGIMiddleware, WSGIResponder, build_environ

PREFETCH_BYTES = 64 * 1024  # a declared body up to this is read before the thread starts


class OneHopWSGI(WSGIMiddleware):
    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            return await super().__call__(scope, receive, send)
        responder = OneHopResponder(self.app, self.executor, self.send_queue_size)
        return await responder(scope, receive, send)


class OneHopResponder(WSGIResponder):
    status: tuple[int, list] | None = None

    async def __call__(self, scope, receive, send) -> None:
        body = await prefetched_body(self.loop, scope, receive)
        environ = build_environ(scope, body)
        sender = self.loop.create_task(self.sender(send))
        try:
            func = functools.partial(contextvars.copy_context().run, self.respond)
            whole = await self.loop.run_in_executor(self.executor, func, environ)
            if whole is not None:
                for message in whole:
                    await send(message)
            await self.send_queue.put(None)
            await sender
        finally:
            if not sender.done():
                sender.cancel()

    def respond(self, environ) -> list[dict] | None:
        """The whole response as messages, or None once a streamed one has been sent."""
        response = self.app(environ, self.start_response)
        try:
            if getattr(response, "streaming", True):  # a file, an export: chunk by chunk
                self.send(self._start_message())
                for chunk in response:
                    self.send({"type": "http.response.body", "body": chunk, "more_body": True})
                self.send({"type": "http.response.body", "body": b""})
                return None
            content = b"".join(response)
        finally:
            getattr(response, "close", lambda: None)()
        return [self._start_message(), {"type": "http.response.body", "body": content}]

    def start_response(self, status, response_headers, exc_info=None):
        # Nothing is sent before the response is whole: a later call (exc_info) replaces it.
        code = int(status.split(" ", 1)[0])
        headers = [
            (name.strip().encode("latin1").lower(), value.strip().encode("latin1"))
            for name, value in response_headers
        ]
        self.status = (code, headers)
        return self._write_unsupported

    def _start_message(self) -> dict:
        code, headers = self.status
        return {"type": "http.response.start", "status": code, "headers": headers}

    @staticmethod
    def _write_unsupported(_chunk):
        raise NotImplementedError("write() of WSGI's start_response: Django never calls it")


async def prefetched_body(loop: asyncio.AbstractEventLoop, scope, receive):
    """The request's body, read here when it declares a small length; else read on demand
    from the thread (each read a crossing, as in a2wsgi)."""
    length = dict(scope.get("headers", ())).get(b"content-length", b"")
    if not length.isdigit() or int(length) > PREFETCH_BYTES:
        return Body(loop, receive)
    data, more = bytearray(), True
    while more:
        message = await receive()
        if message["type"] == "http.disconnect":
            break
        data += message.get("body", b"")
        more = message.get("more_body", False)
    return io.BytesIO(data)
