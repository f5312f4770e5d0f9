"""Find devices that look like robots this layer drives: ``robotide robots detect``.

Serial ports come from pyserial's port list (USB vendor and product ids, names); USB devices
that are not serial ports (a Lego NXT, USB-CAN adapters), CAN network interfaces and sound
cards come from the kernel's sysfs and procfs. Each finding suggests a robot URL; a guess
from a generic USB-serial adapter says so. Nothing is opened: detecting must never move a
robot or disturb a program using a port.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

#: (vendor id, product id or None for any) -> (what it is, URL template with {device}).
SERIAL_IDS: dict[tuple[int, int | None], tuple[str, str]] = {
    (0x26AC, None): ("Pixhawk autopilot (3D Robotics ids)", "mavlink://{device}?baud=115200"),
    (0x1209, 0x5740): ("ArduPilot autopilot", "mavlink://{device}?baud=115200"),
    (0x1209, 0x5741): ("ArduPilot autopilot (bootloader)", "mavlink://{device}?baud=115200"),
    (0x2DAE, None): ("CubePilot autopilot", "mavlink://{device}?baud=115200"),
    (0x3162, None): ("Holybro autopilot", "mavlink://{device}?baud=115200"),
    (0x0403, 0x6015): ("SiK telemetry radio (FTDI)", "mavlink://{device}?baud=57600"),
    (0x16D0, 0x117E): ("CANable USB-CAN adapter (slcan)", "can://slcan{device}"),
    (0x0483, 0x5740): ("USB-CAN adapter, STM32 serial (slcan?)", "can://slcan{device}"),
}
#: Generic USB-serial chips: a Pioneer's usual cable, but many things use them.
SERIAL_ADAPTERS: dict[tuple[int, int], str] = {
    (0x0403, 0x6001): "FTDI FT232",
    (0x067B, 0x2303): "Prolific PL2303",
    (0x10C4, 0xEA60): "Silicon Labs CP210x",
    (0x1A86, 0x7523): "WCH CH340",
}
#: USB devices that are not serial ports.
USB_IDS: dict[tuple[int, int], tuple[str, str]] = {
    (0x0694, 0x0002): ("Lego Mindstorms NXT brick", "nxt://usb/{serial}"),
    (0x1D50, 0x606F): ("candleLight / gs_usb USB-CAN adapter", "can://gs_usb/0"),
    (0x0C72, 0x000C): ("PEAK PCAN-USB adapter", "can://pcan/PCAN_USBBUS1"),
}
ARPHRD_CAN = 280  # the link type of a CAN network interface


@dataclass(frozen=True)
class Finding:
    device: str
    looks_like: str
    url: str
    sure: bool  # False: a generic device, the URL is a guess to check

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def detect(root: Path | str = "/", ports: list[Any] | None = None) -> list[Finding]:
    """Everything that looks like a robot, under the filesystem ``root`` (tests give a tree)."""
    root = Path(root)
    if ports is None:
        from serial.tools import list_ports

        ports = list_ports.comports()
    return [
        *serial_findings(ports),
        *rfcomm_findings(root),
        *usb_findings(root),
        *can_findings(root),
        *sound_findings(root),
    ]


def serial_findings(ports: list[Any]) -> list[Finding]:
    found = []
    for port in sorted(ports, key=lambda p: p.device):
        if port.vid is None:
            continue  # a built-in UART: nothing says what is on it
        ids = (port.vid, port.pid)
        known = SERIAL_IDS.get(ids) or SERIAL_IDS.get((port.vid, None))
        if known:
            what, url = known
            found.append(Finding(port.device, what, url.format(device=port.device), True))
        elif ids in SERIAL_ADAPTERS:
            what = f"{SERIAL_ADAPTERS[ids]} USB-serial adapter: a Pioneer's cable, or another"
            found.append(Finding(port.device, what, f"pioneer://{port.device}", False))
        elif port.device.startswith("/dev/ttyACM"):
            what = f"USB modem-class serial device ({port.description})"
            found.append(Finding(port.device, what, f"mavlink://{port.device}", False))
    return found


def rfcomm_findings(root: Path) -> list[Finding]:
    """Bluetooth serial links bound with rfcomm: how an NXT is reached over Bluetooth."""
    return [
        Finding(
            f"/dev/{path.name}", "Bluetooth serial link (an NXT?)", f"nxt:///dev/{path.name}", False
        )
        for path in sorted((root / "dev").glob("rfcomm*"))
    ]


def usb_findings(root: Path) -> list[Finding]:
    found = []
    for device in sorted((root / "sys/bus/usb/devices").glob("*")):
        vid, pid = _hex(device / "idVendor"), _hex(device / "idProduct")
        if (vid, pid) in USB_IDS:
            what, url = USB_IDS[(vid, pid)]
            serial = _text(device / "serial") or ""
            found.append(Finding(f"usb {device.name}", what, url.format(serial=serial), True))
    return found


def can_findings(root: Path) -> list[Finding]:
    found = []
    for interface in sorted((root / "sys/class/net").glob("*")):
        if _text(interface / "type") == str(ARPHRD_CAN):
            state = _text(interface / "operstate") or "unknown"
            what = f"CAN network interface ({state}): a CiA 402 or DBC base"
            found.append(Finding(interface.name, what, f"can://socketcan/{interface.name}", True))
    return found


def sound_findings(root: Path) -> list[Finding]:
    """Sound cards: each can play the tones of a DTMF robot."""
    cards = _text(root / "proc/asound/cards") or ""
    found = []
    for line in cards.splitlines():
        number, _, rest = line.strip().partition(" ")
        if number.isdigit() and "]:" in rest:
            name = rest.split("]:", 1)[1].strip()
            what = f"sound card {number}: {name} (a DTMF robot's audio cable)"
            found.append(Finding(f"card {number}", what, f"dtmf://?device=hw:{number}", False))
    return found


def _text(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None


def _hex(path: Path) -> int | None:
    text = _text(path)
    try:
        return int(text, 16) if text else None
    except ValueError:
        return None
