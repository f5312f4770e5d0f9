"""An ``X-Robotide-Worker: HOST:PID`` header on every response and websocket handshake: which
web worker served it, for whoever looks into load balancing (and for the fleet tests)."""

import os
import socket


class ServedBy:
    def __init__(self, app):
        self.app = app
        self.header = (b"x-robotide-worker", f"{socket.gethostname()}:{os.getpid()}".encode())

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)

        async def send_marked(message):
            if message["type"] in ("http.response.start", "websocket.accept"):
                message = {**message, "headers": [*message.get("headers", []), self.header]}
            await send(message)

        return await self.app(scope, receive, send_marked)
