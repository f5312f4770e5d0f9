"""Python client for the robotide Robot API (standard library only).

import robot
bot = robot.Robot()
bot.drive(0.2, 0.0)             # linear m/s, angular rad/s (clamped to the robot's limits)
print(bot.sensors()["heading"])  # compass, degrees
bot.show("heading", 42)          # appears live on the robot's page
bot.stop()
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


class Robot:
    def __init__(self, address=None, token=None):
        address = address or os.environ.get("ROBOT_API")  # unix:/path or host:port
        token = token or os.environ.get("ROBOT_TOKEN")
        if not address or not token:
            raise RobotError(
                "ROBOT_API and ROBOT_TOKEN are not set: run this program from robotide"
            )
        if address.startswith("unix:"):
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            self._sock.connect(address[len("unix:") :])
        else:
            host, _, port = address.rpartition(":")
            self._sock = socket.create_connection((host or "127.0.0.1", int(port)))
            self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._file = self._sock.makefile("rb")
        self._next_id = 0
        self.call("auth", token)

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

    def close(self):
        self._file.close()
        self._sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
