"""Pages and the API through Django's WSGI handler, websockets through Channels, one server.

The live camera (``/robots/<name>/camera.mjpg``) is an endless response: it is answered on the
event loop by a Channels consumer, so a viewer never holds one of the WSGI worker threads.

Django's ASGI handler hops between the event loop and a thread for each of its (sync)
middlewares, about 4 ms per request here; under WSGI a request is one hop to a worker thread
(robotide.wsgi_bridge).
"""

import os

from django.core.wsgi import get_wsgi_application

from robotide.wsgi_bridge import OneHopWSGI

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "robotide.settings")
django_http_app = OneHopWSGI(get_wsgi_application(), workers=8)

from channels.auth import AuthMiddlewareStack  # noqa: E402
from channels.routing import ProtocolTypeRouter, URLRouter  # noqa: E402
from channels.security.websocket import AllowedHostsOriginValidator  # noqa: E402
from django.urls import path, re_path  # noqa: E402

from programs.consumers import ConsoleConsumer, RunConsumer, RunListConsumer  # noqa: E402
from robotide.language import WebsocketLanguage  # noqa: E402
from robotide.security import SameOriginWebsocket  # noqa: E402
from robotide.served_by import ServedBy  # noqa: E402
from robotide.ws_user import LazyAuthMiddlewareStack  # noqa: E402
from robots.camera import CameraStream  # noqa: E402
from robots.consumers import RobotConsumer  # noqa: E402

websocket_urlpatterns = [
    path("ws/runs/", RunListConsumer.as_asgi()),
    path("ws/runs/<int:run_id>/", RunConsumer.as_asgi()),
    path("ws/programs/<int:program_id>/console/", ConsoleConsumer.as_asgi()),
    path("ws/robots/<slug:name>/", RobotConsumer.as_asgi()),
]

http_urlpatterns = [
    path("robots/<slug:name>/camera.mjpg", AuthMiddlewareStack(CameraStream.as_asgi())),
    re_path(r"", django_http_app),  # everything else
]

application = ServedBy(
    ProtocolTypeRouter(
        {
            "http": URLRouter(http_urlpatterns),
            "websocket": SameOriginWebsocket(
                AllowedHostsOriginValidator(
                    LazyAuthMiddlewareStack(WebsocketLanguage(URLRouter(websocket_urlpatterns)))
                )
            ),
        }
    )
)
