"""Python client for the robotide Robot API (standard library only).

import robot
bot = robot.Robot()
bot.drive(0.2, 0.0)             # linear m/s, angular rad/s (clamped to the robot's limits)
print(bot.sensors()["heading"])  # compass, degrees
bot.show("heading", 42)          # appears live on the robot's page
bot.stop()

Programs on the same robot cooperate through messages and a shared memory:
bot.subscribe("speed")           # this connection gets what is published on "speed"
bot.receive("speed", 5.0)        # the next value, or None after 5 s (no timeout: wait)
bot.publish("speed", 0.2)        # any JSON value; returns how many subscribers it reached
bot.memory_set("laps", 3)
bot.memory_get("laps")           # 3, or None if nothing is kept under that key

The robot's computer lends its senses and voice:
bot.say("I'm home")              # spoken, and shown on the robot's page
bot.snapshot()                   # {"jpeg": base64 text, "width": .., "height": ..}
bot.scan_barcode()               # [{"text": "home", "format": "QRCode", "position": [...]}]
bot.listen(3, words=["move", "stop"])  # {"text": "move", "words": ["move"]}
"""

import json
import os
import socket

__all__ = ["Robot", "RobotError"]

_encode = json.JSONEncoder(separators=(",", ":")).encode


class RobotError(Exception):
    """An error the robot reported, e.g. a sensor it does not have."""

    def __init__(self, message, code=None, data=None):
        super().__init__(message)
        self.code = code
        self.data = data


def _connect(address):
    """A socket connected to `address`: unix:/path or host:port."""
    if address.startswith("unix:"):
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.connect(address[len("unix:") :])
        except OSError:
            sock.close()
            raise
        return sock
    host, _, port = address.rpartition(":")
    sock = socket.create_connection((host or "127.0.0.1", int(port)))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


class Robot:
    def __init__(self, address=None, token=None):
        address = address or os.environ.get("ROBOT_API")  # unix:/path or host:port
        token = token or os.environ.get("ROBOT_TOKEN")
        if not address or not token:
            raise RobotError(
                "ROBOT_API and ROBOT_TOKEN are not set: run this program from robotide"
            )
        self._sock = _connect(address)
        self._file = self._sock.makefile("rb")
        self._next_id = 0
        try:
            self.call("auth", token)
        except BaseException:
            self.close()
            raise

    def call(self, method, *params):
        self._next_id += 1
        request = {"jsonrpc": "2.0", "id": self._next_id, "method": method, "params": list(params)}
        self._sock.sendall(_encode(request).encode() + b"\n")
        line = self._file.readline()
        if not line:
            raise RobotError("the robot closed the connection (the run has ended?)")
        reply = json.loads(line)
        if "error" in reply:
            error = reply["error"]
            raise RobotError(
                error.get("message", "robot error"), error.get("code"), error.get("data")
            )
        return reply.get("result")

    def drive(self, linear, angular=0.0):
        """Drive at `linear` m/s and `angular` rad/s; returns the speeds actually applied."""
        return self.call("drive", linear, angular)

    def stop(self):
        return self.call("stop")

    def sensors(self):
        """All readings as a dict: heading (deg), range (m), position {x, y, theta}, ..."""
        return self.call("sensors")

    def sensor(self, name):
        return self.call("sensor", name)

    def capabilities(self):
        return self.call("capabilities")

    def show(self, name, value):
        """Publish a number, a text or an SVG drawing (a string starting with <svg) by name."""
        return self.call("show", name, value)

    def publish(self, topic, value):
        """Send `value` (any JSON) to the programs subscribed to `topic`; returns how many."""
        return self.call("publish", topic, value)

    def subscribe(self, topic):
        """From now on this connection gets what is published on `topic` (see receive)."""
        return self.call("subscribe", topic)

    def receive(self, topic, timeout=None):
        """The next value published on a subscribed topic; None after `timeout` seconds
        (None: wait for ever)."""
        return self.call("receive", topic, timeout)

    def memory_set(self, key, value):
        """Keep `value` (any JSON) under `key` in the memory the robot's programs share."""
        return self.call("memory_set", key, value)

    def memory_get(self, key):
        """The value kept under `key`, or None."""
        return self.call("memory_get", key)

    def say(self, text):
        """Speak `text` (shown on the robot's page too); returns {"spoken": True or False,
        "seconds": .., or "reason": why not}."""
        return self.call("say", text)

    def snapshot(self):
        """The camera's frame now: {"jpeg": the JPEG in base64, "width": .., "height": ..}."""
        return self.call("snapshot")

    def scan_barcode(self):
        """The barcodes and QR codes in view: a list of {"text", "format", "position"}."""
        return self.call("scan_barcode")

    def listen(self, seconds=5, wav=None, words=None):
        """Recognise speech: `seconds` from the microphone, or the WAV file `wav` in the
        program's folder; `words` (a list) listens for those only. Returns {"text", "words"}:
        with `words`, the text is one of them, or "" if none was heard."""
        return self.call("listen", seconds, wav, words)

    def close(self):
        self._file.close()
        self._sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
