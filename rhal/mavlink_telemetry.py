"""Receiving for the mavlink:// driver: MAVLink messages from the vehicle into readings."""

from __future__ import annotations

import math
import time
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

ARDUPILOT, PX4 = "ardupilot", "px4"


class MavlinkTelemetry:
    """The MavlinkRobot half that parses what the vehicle sends and keeps the readings."""

    # -- receiving -------------------------------------------------------------------------

    def _receive(self, data: bytes) -> None:
        """Parse bytes from the link; bad frames are only counted (robust parsing)."""
        try:
            messages = self._parser.parse_buffer(data) or []
        except mavlink2.MAVError:  # not raised with robust parsing; a safety net all the same
            self._parser.total_receive_errors += 1
            self._parser.buf, self._parser.buf_index = bytearray(), 0
            return
        for message in messages:
            handler = self._handlers.get(message.get_type())
            if handler is not None:
                handler(self, message)

    def _on_heartbeat(self, msg: Any) -> None:
        system, component = msg.get_srcSystem(), msg.get_srcComponent()
        if system == self.sysid or msg.autopilot == mavlink2.MAV_AUTOPILOT_INVALID:
            return  # a GCS, a camera, a gimbal, or our own echo: not the vehicle
        if not self.vehicle:
            self.vehicle = {
                "system": system,
                "component": component,
                "autopilot": _autopilot_name(msg.autopilot),
                "type": _enum_name("MAV_TYPE", msg.type),
            }
        if (system, component) != (self.vehicle["system"], self.vehicle["component"]):
            return
        r = self._readings
        r["heartbeat_at"] = time.monotonic()
        r["base_mode"], r["custom_mode"] = msg.base_mode, msg.custom_mode
        r["armed"] = bool(msg.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
        r["mode"] = mavutil.mode_string_v10(msg)
        if self._engaged and not self._in_control():
            self._engaged = False
            self._taken_over = (
                f"the vehicle at {self.url!r} is now {self._state_text()}: an RC transmitter, "
                f"another GCS or a failsafe took it over; the driver does not take it back "
                f"until stop() is called"
            )
            if self._setpoint[:2] != (0.0, 0.0):
                self._setpoint = (0.0, 0.0, self._next_stamp())

    def _from_vehicle(self, msg: Any) -> bool:
        return bool(self.vehicle) and msg.get_srcSystem() == self.vehicle["system"]

    def _on_attitude(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            self._readings["yaw"] = _finite(msg.yaw)
            self._readings["yawspeed"] = _finite(msg.yawspeed)

    def _on_vfr_hud(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            self._readings["hud_heading"] = float(msg.heading % 360)

    def _on_local_position(self, msg: Any) -> None:
        values = [_finite(v) for v in (msg.x, msg.y, msg.vx, msg.vy)]
        if self._from_vehicle(msg) and None not in values:
            self._readings["local"] = tuple(values)

    def _on_global_position(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            self._readings["global"] = (msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0)

    def _on_gps_raw(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            satellites = None if msg.satellites_visible == 255 else msg.satellites_visible
            position = (msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0)
            self._readings["gps_raw"] = (msg.fix_type, satellites, position)

    def _on_sys_status(self, msg: Any) -> None:
        if self._from_vehicle(msg) and msg.voltage_battery != 0xFFFF:
            self._readings["battery"] = msg.voltage_battery / 1000.0

    def _on_distance_sensor(self, msg: Any) -> None:
        if self._from_vehicle(msg) and msg.orientation == mavlink2.MAV_SENSOR_ROTATION_NONE:
            beyond = msg.max_distance and msg.current_distance >= msg.max_distance
            self._readings["range"] = None if beyond else msg.current_distance / 100.0

    def _on_statustext(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            text = msg.text.strip()
            self._texts.append(text)
            self._text_log.append((msg.severity, text))
            del self._text_log[:-50]

    def _on_command_ack(self, msg: Any) -> None:
        if not self._from_vehicle(msg) or msg.target_system not in (0, self.sysid):
            return  # an answer to another GCS
        future = self._pending.get(msg.command)
        if future is not None and not future.done():
            if msg.result != mavlink2.MAV_RESULT_IN_PROGRESS:  # the final answer follows
                future.set_result(msg.result)

    _handlers = {
        "HEARTBEAT": _on_heartbeat,
        "ATTITUDE": _on_attitude,
        "VFR_HUD": _on_vfr_hud,
        "LOCAL_POSITION_NED": _on_local_position,
        "GLOBAL_POSITION_INT": _on_global_position,
        "GPS_RAW_INT": _on_gps_raw,
        "SYS_STATUS": _on_sys_status,
        "DISTANCE_SENSOR": _on_distance_sensor,
        "STATUSTEXT": _on_statustext,
        "COMMAND_ACK": _on_command_ack,
    }

    # -- readings --------------------------------------------------------------------------

    def _reset_readings(self) -> None:
        self._readings: dict[str, Any] = {
            "heartbeat_at": None,
            "base_mode": 0,
            "custom_mode": None,
            "armed": None,
            "mode": None,
            "yaw": None,
            "yawspeed": None,
            "hud_heading": None,
            "local": None,  # north, east, v_north, v_east
            "global": None,  # lat, lon, alt
            "gps_raw": None,  # fix, satellites, (lat, lon, alt)
            "battery": None,
            "range": None,
        }

    def _gps(self) -> dict[str, Any] | None:
        fused, raw = self._readings["global"], self._readings["gps_raw"]
        if fused is None and raw is None:
            return None
        lat, lon, alt = fused if fused is not None else raw[2]
        fix, satellites = (raw[0], raw[1]) if raw is not None else (None, None)
        return {"lat": lat, "lon": lon, "alt": alt, "fix": fix, "satellites": satellites}


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _enum_name(enum: str, value: int) -> str:
    entry = mavlink2.enums.get(enum, {}).get(value)
    prefix = enum + "_"
    return entry.name.removeprefix(prefix) if entry is not None else str(value)


def _autopilot_name(value: int) -> str:
    if value == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT
    if value == mavlink2.MAV_AUTOPILOT_PX4:
        return PX4
    return _enum_name("MAV_AUTOPILOT", value)


def _result_name(result: int | None) -> str:
    return "no answer" if result is None else _enum_name("MAV_RESULT", result)
