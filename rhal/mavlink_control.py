"""Taking the vehicle for the mavlink:// driver: guided mode, arming, setpoints, commands."""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from rhal.errors import RhalError
from rhal.mavlink_telemetry import ARDUPILOT, PX4, _result_name

ACK_WAIT = 1.0  # s to wait for a COMMAND_ACK before trying again
RETRY_PAUSE = 0.5  # s between refused attempts to switch mode or arm
PX4_PRESTREAM = 5  # setpoints PX4 must have had before it accepts OFFBOARD

ROVER_GUIDED = 15  # ArduPilot Rover's custom_mode for GUIDED
PX4_MAIN_OFFBOARD = 6  # PX4's custom main mode for OFFBOARD (bits 16-23 of custom_mode)

#: SET_POSITION_TARGET_LOCAL_NED type_mask: ignore position (bits 0-2), acceleration (6-8) and
#: yaw (10); use velocity vx, vy, vz (3-5) and yaw_rate (11). 0x05C7 = 1479. ArduPilot Rover
#: reads this combination as "speed and turn rate" (set_desired_turn_rate_and_speed).
VELOCITY_YAW_RATE_MASK = (
    mavlink2.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_YAW_IGNORE
)


class VehicleControlError(RhalError):
    """The vehicle would not be taken under the program's control: it refused the guided mode
    or arming (the autopilot's own reason is in the message), or someone else took it over."""


class MavlinkControl:
    """The MavlinkRobot half that takes the vehicle and streams its setpoints."""

    # -- taking the vehicle ----------------------------------------------------------------

    async def _engage(self) -> None:
        """Get the vehicle into its guided mode and armed, or raise VehicleControlError."""
        async with self._engage_lock:
            if self._engaged:
                return
            if self.vehicle.get("autopilot") not in (ARDUPILOT, PX4):
                raise VehicleControlError(
                    f"the autopilot at {self.url!r} ({self.vehicle.get('autopilot')}) is not "
                    f"one this driver can drive: ArduPilot or PX4"
                )
            if not self.arm:
                if not self._in_control():
                    raise VehicleControlError(
                        f"the vehicle at {self.url!r} is {self._state_text()}; with arm=false "
                        f"the driver does not arm it or change its mode: arm it and switch it "
                        f"to {self._guided_name()} first (RC transmitter or GCS)"
                    )
                self._engaged = True
                return
            stops, deadline = self._stops, time.monotonic() + self.arm_timeout
            self._text_log = []
            if self.vehicle["autopilot"] == PX4:
                await self._prestream(deadline)
            while not self._in_control():
                r = self._readings
                if not self._in_mode():
                    what = f"switch to {self._guided_name()}"
                    result = await self._command(mavlink2.MAV_CMD_DO_SET_MODE, *self._mode_params())
                    if result == mavlink2.MAV_RESULT_ACCEPTED:
                        # The next HEARTBEAT will say so too; the ack was sent after the switch.
                        r["base_mode"] |= mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                        r["custom_mode"] = self._guided_custom_mode()
                        r["mode"] = self._guided_name()
                else:
                    what = "arm"
                    result = await self._command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
                    if result == mavlink2.MAV_RESULT_ACCEPTED:
                        self._we_armed = True
                        r["armed"] = True
                if stops != self._stops:
                    return  # drive() sees it and says so
                if result == mavlink2.MAV_RESULT_ACCEPTED:
                    continue
                if result == mavlink2.MAV_RESULT_UNSUPPORTED or time.monotonic() >= deadline:
                    raise VehicleControlError(self._refused(what, result))
                await asyncio.sleep(max(0.0, min(RETRY_PAUSE, deadline - time.monotonic())))
                if stops != self._stops:
                    return
            self._engaged = True

    async def _prestream(self, deadline: float) -> None:
        """PX4 takes OFFBOARD only once setpoints stream; the pump streams from link-up."""
        while self._setpoints_sent < PX4_PRESTREAM and time.monotonic() < deadline:
            self._require_link()
            await asyncio.sleep(1.0 / self.setpoint_rate)

    def _refused(self, what: str, result: int | None) -> str:
        # The autopilot says why in a STATUSTEXT ("PreArm: GPS: No fix"); the ack only says no.
        serious = [text for severity, text in self._text_log if severity <= 4]
        texts = serious or [text for _, text in self._text_log]
        reason = texts[-1] if texts else "it gave no reason"
        answer = "no COMMAND_ACK" if result is None else f"COMMAND_ACK {_result_name(result)}"
        return (
            f"the vehicle at {self.url!r} would not {what} within {self.arm_timeout:g} s: "
            f"{reason} ({answer})"
        )

    def _in_mode(self) -> bool:
        custom = self._readings["custom_mode"]
        if custom is None:
            return False
        if self.vehicle.get("autopilot") == PX4:
            return (custom >> 16) & 0xFF == PX4_MAIN_OFFBOARD
        return custom == ROVER_GUIDED and bool(self._readings["base_mode"] & 1)

    def _in_control(self) -> bool:
        return self._in_mode() and bool(self._readings["armed"])

    def _mode_params(self) -> tuple[int, int, int]:
        """MAV_CMD_DO_SET_MODE's base mode, custom (main) mode and PX4 sub mode."""
        main = PX4_MAIN_OFFBOARD if self.vehicle.get("autopilot") == PX4 else ROVER_GUIDED
        return mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, 0

    def _guided_custom_mode(self) -> int:
        """HEARTBEAT.custom_mode in that mode: PX4 keeps its main mode in bits 16-23."""
        if self.vehicle.get("autopilot") == PX4:
            return PX4_MAIN_OFFBOARD << 16
        return ROVER_GUIDED

    def _guided_name(self) -> str:
        return "OFFBOARD" if self.vehicle.get("autopilot") == PX4 else "GUIDED"

    def _state_text(self) -> str:
        armed = "armed" if self._readings["armed"] else "disarmed"
        return f"in {self._readings['mode'] or 'an unknown mode'} and {armed}"

    # -- setpoints and commands ------------------------------------------------------------

    async def _set_point(self, linear: float, angular: float) -> None:
        self._setpoint = (linear, angular, self._next_stamp())
        await self._send(self._setpoint_frame())

    def _next_stamp(self) -> int:
        now = int((time.monotonic() - self._epoch) * 1000)
        return max(now, self._setpoint[2] + 1) % 2**32 or 1

    def _setpoint_frame(self) -> bytes:
        linear, angular, stamp = self._setpoint
        self._setpoints_sent += 1
        return self._encode(
            mavlink2.MAVLink_set_position_target_local_ned_message(
                stamp,
                self.vehicle.get("system", 1),
                self.vehicle.get("component", 1),
                mavlink2.MAV_FRAME_BODY_NED,
                VELOCITY_YAW_RATE_MASK,
                0.0, 0.0, 0.0,
                linear, 0.0, 0.0,  # body frame: x forward
                0.0, 0.0, 0.0,
                0.0,
                0.0 - angular,  # NED yaw rate is clockwise seen from above
            )
        )  # fmt: skip

    def _streaming(self) -> bool:
        # PX4 wants setpoints before it enters OFFBOARD, so they stream from link-up; an
        # ArduPilot Rover only while we hold it in GUIDED.
        return self._engaged or self.vehicle.get("autopilot") == PX4

    async def _command(self, command: int, *params: float) -> int | None:
        """Send COMMAND_LONG; the result of its COMMAND_ACK, or None if none came."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[int] = loop.create_future()
        self._pending[command] = future
        try:
            for confirmation in range(2):
                args = (list(params) + [0.0] * 7)[:7]
                await self._send(
                    self._encode(
                        mavlink2.MAVLink_command_long_message(
                            self.vehicle.get("system", 1),
                            self.vehicle.get("component", 1),
                            command,
                            confirmation,
                            *args,
                        )
                    )
                )
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(ACK_WAIT):
                        return await asyncio.shield(future)
            return None
        finally:
            if self._pending.get(command) is future:
                del self._pending[command]

    def _encode(self, message: Any) -> bytes:
        frame = message.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return frame

    def _heartbeat_frame(self) -> bytes:
        return self._encode(
            mavlink2.MAVLink_heartbeat_message(
                mavlink2.MAV_TYPE_GCS,
                mavlink2.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink2.MAV_STATE_ACTIVE,
                3,
            )
        )
