"""The nxt:// driver's session: every blocking nxt-python call, run on the worker thread."""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Any

import nxt.brick
import nxt.error
import nxt.motor
import nxt.sensor
import nxt.sensor.generic
from nxt.motor import Mode, RegulationMode, RunState

from rhal.nxt_links import _open_brick

if TYPE_CHECKING:
    from rhal.nxt_brick import NxtRobot

MOTOR_PORTS = {"A": nxt.motor.Port.A, "B": nxt.motor.Port.B, "C": nxt.motor.Port.C}


class _Session:
    """One connection to a brick: every blocking nxt-python call, run on the worker thread."""

    def __init__(self, robot: NxtRobot) -> None:
        self.robot = robot
        self.brick: nxt.brick.Brick | None = None
        self.sensors: dict[str, Any] = {}

    def connect(self) -> dict[str, Any]:
        robot = self.robot
        self.brick = _open_brick(robot)
        brick = self.brick
        sleep_ms = brick.keep_alive()
        (prot_major, prot_minor), (fw_major, fw_minor) = brick.get_firmware_version()
        name, address, _, _ = brick.get_device_info()
        self.motors_off()  # the NXT keeps running what it was last told, even without us
        ports = robot.sensor_ports
        generic = nxt.sensor.generic
        if "ultrasonic" in ports:
            port = _input(ports["ultrasonic"])
            self.sensors["ultrasonic"] = generic.Ultrasonic(brick, port, check_compatible=False)
        if "touch" in ports:
            self.sensors["touch"] = generic.Touch(brick, _input(ports["touch"]))
        if "light" in ports:
            light = generic.Light(brick, _input(ports["light"]), illuminated=robot.floodlight)
            lamp = "LIGHT_ACTIVE" if robot.floodlight else "LIGHT_INACTIVE"
            # Percent (0 dark .. 100 bright) rather than nxt-python's raw 0..1023.
            light.set_input_mode(nxt.sensor.Type[lamp], nxt.sensor.Mode.PERCENT)
            self.sensors["light"] = light
        if "sound" in ports:
            sound = generic.Sound(brick, _input(ports["sound"]), adjusted=True)
            sound.set_input_mode(nxt.sensor.Type.SOUND_DBA, nxt.sensor.Mode.PERCENT)
            self.sensors["sound"] = sound
        return {
            "name": name,
            "address": address,
            "firmware": f"{fw_major}.{fw_minor}",
            "protocol": f"{prot_major}.{prot_minor}",
            "sleep_timeout_ms": sleep_ms,
        }

    def close(self) -> None:
        brick, self.brick = self.brick, None
        if brick is not None:
            with contextlib.suppress(OSError):
                brick.close()

    def _brick(self) -> nxt.brick.Brick:
        if self.brick is None:
            raise ConnectionResetError("the link is closed")
        return self.brick

    # -- motors ----------------------------------------------------------------------------

    def run(self, left: int, right: int) -> None:
        robot = self.robot
        for port, power, reverse in (
            (robot.left, left, robot.reverse_left),
            (robot.right, right, robot.reverse_right),
        ):
            self._brick().set_output_state(
                MOTOR_PORTS[port],
                -power if reverse else power,
                Mode.ON | Mode.REGULATED,
                RegulationMode.SPEED,
                0,
                RunState.RUNNING,
                nxt.motor.LIMIT_RUN_FOREVER,
            )

    def stop(self, brake: bool) -> None:
        """The stop command: power 0, motors on, braked (or floating), on both motors."""
        if brake:
            mode, regulation = Mode.ON | Mode.BRAKE | Mode.REGULATED, RegulationMode.SPEED
        else:
            mode, regulation = Mode.ON, RegulationMode.IDLE
        for port in (self.robot.left, self.robot.right):
            self._brick().set_output_state(
                MOTOR_PORTS[port], 0, mode, regulation, 0, RunState.RUNNING, 0
            )

    def motors_off(self) -> None:
        """Both drive motors off (not powered, not braked), as when the brick starts."""
        for port in (self.robot.left, self.robot.right):
            self._brick().set_output_state(
                MOTOR_PORTS[port], 0, Mode.IDLE, RegulationMode.IDLE, 0, RunState.IDLE, 0
            )

    def rotation(self, port: str) -> int:
        """The motor's rotation count: degrees since the brick started its program."""
        state = self._brick().get_output_state(MOTOR_PORTS[port])
        if state[0] != MOTOR_PORTS[port]:
            raise nxt.error.ProtocolError(f"asked for motor {port}, got {state[0].name}")
        return state[9]

    # -- sensors ---------------------------------------------------------------------------

    def distance(self) -> int:
        """Centimetres to the nearest echo; 255 when nothing is in reach; -1 on I2C errors."""
        try:
            return self.sensors["ultrasonic"].get_distance()
        except nxt.error.DirectProtocolError:  # the sensor did not answer on the I2C bus
            return -1

    def analog(self, kind: str) -> int | None:
        """The scaled value (bool, percent) of an analog sensor, None until it is valid."""
        sensor = self.sensors[kind]
        values = sensor.get_input_values()
        if values.port != sensor._port:
            raise nxt.error.ProtocolError(f"asked for sensor {sensor._port}, got {values.port}")
        return values.scaled_value if values.valid else None

    def battery(self) -> int:
        return self._brick().get_battery_level()

    def keep_alive(self) -> int:
        return self._brick().keep_alive()


def _input(port: int) -> nxt.sensor.Port:
    return nxt.sensor.Port(port - 1)
