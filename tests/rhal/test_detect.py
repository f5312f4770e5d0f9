"""`robotide robots detect` on a made-up machine: a sysfs/procfs tree and pyserial port infos."""

import json
import subprocess
import sys

from serial.tools.list_ports_common import ListPortInfo

from rhal.detect import detect


def port(device, vid=None, pid=None, description="n/a"):
    info = ListPortInfo(device, skip_link_detection=True)
    info.vid, info.pid, info.description = vid, pid, description
    return info


def write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text + "\n")


def machine(root):
    usb = root / "sys/bus/usb/devices"
    write(usb / "1-1/idVendor", "0694")
    write(usb / "1-1/idProduct", "0002")
    write(usb / "1-1/serial", "00165312ABCD")
    write(usb / "1-2/idVendor", "046d")  # a mouse
    write(usb / "1-2/idProduct", "c077")
    write(root / "sys/class/net/can0/type", "280")
    write(root / "sys/class/net/can0/operstate", "up")
    write(root / "sys/class/net/eth0/type", "1")
    write(
        root / "proc/asound/cards",
        " 0 [PCH            ]: HDA-Intel - HDA Intel PCH\n"
        "                      HDA Intel PCH at 0xf7f10000 irq 32",
    )
    (root / "dev").mkdir()
    (root / "dev/rfcomm0").touch()
    return [
        port("/dev/ttyACM0", 0x1209, 0x5740, "ArduPilot"),
        port("/dev/ttyUSB0", 0x0403, 0x6001, "FT232R USB UART"),
        port("/dev/ttyACM1", 0x16D0, 0x117E, "CANable"),
        port("/dev/ttyS0"),  # a built-in UART: nothing to go on
    ]


def test_each_kind_of_robot_is_found_with_a_url(tmp_path):
    ports = machine(tmp_path)
    found = {f.device: f for f in detect(tmp_path, ports)}
    assert set(found) == {
        "/dev/ttyACM0",
        "/dev/ttyUSB0",
        "/dev/ttyACM1",
        "/dev/rfcomm0",
        "usb 1-1",
        "can0",
        "card 0",
    }
    assert found["/dev/ttyACM0"].url == "mavlink:///dev/ttyACM0?baud=115200"
    assert found["/dev/ttyACM0"].sure
    assert found["/dev/ttyUSB0"].url == "pioneer:///dev/ttyUSB0"
    assert not found["/dev/ttyUSB0"].sure  # any FTDI cable: a guess
    assert found["/dev/ttyACM1"].url == "can://slcan/dev/ttyACM1"
    assert found["/dev/rfcomm0"].url == "nxt:///dev/rfcomm0"
    assert found["usb 1-1"].url == "nxt://usb/00165312ABCD"
    assert found["can0"].url == "can://socketcan/can0"
    assert "HDA Intel PCH" in found["card 0"].looks_like
    assert found["card 0"].url == "dtmf://?device=hw:0"


def test_an_empty_machine_finds_nothing(tmp_path):
    assert detect(tmp_path, []) == []


def test_the_command_prints_json_lines():
    result = subprocess.run(
        [sys.executable, "-m", "robotide.cli", "robots", "detect", "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    for line in result.stdout.splitlines():
        assert set(json.loads(line)) == {"device", "looks_like", "url", "sure"}
