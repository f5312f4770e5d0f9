#!/bin/sh
# Libraries that programs on a MAVLink robot import, for the Python that runs them (python3 of
# the system, as programs/languages.py starts it): pymavlink, so a program can talk to the
# vehicle through the gateway at $ROBOT_MAVLINK. Installed only when missing.
set -eu
python=/usr/bin/python3
if "$python" -c "import pymavlink.mavutil" >/dev/null 2>&1; then
    exit 0
fi
if ! "$python" -m pip --version >/dev/null 2>&1; then
    if [ "$(id -u)" -ne 0 ]; then
        echo "python3-pip is missing (run as root, or install it)" >&2
        exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends python3-pip >/dev/null
fi
# Debian marks its Python as managed by apt; this goes to /usr/local, beside apt's packages.
"$python" -m pip install --quiet --break-system-packages --root-user-action=ignore pymavlink
