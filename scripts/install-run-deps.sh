#!/bin/sh
# What `make run` needs from the machine; $1 is the python3 that makes robotide's virtualenv,
# --quiet (second) leaves out what an ordinary user is told (said once, when robotide starts).
# As root: what is missing is installed from Debian's archive: the venv module (python3-venv:
# a fresh Debian's python3 has none), bubblewrap (the runs' box), slirp4netns and iproute2 (the
# NAT of network 'full'), libfaketime (a sim's runs faster than real time: runbox/timescale.py),
# fonts-dejavu-core (the words on the sim's pictures, accents included).
# As an ordinary user runs are boxed with what every Debian machine has (util-linux's unshare
# and python3); this says what would give them more, and goes on, unless the virtualenv itself
# cannot be made (without libfaketime a sim whose speed is above 1 refuses its runs, saying so).
set -eu
python="${1:-python3}"
quiet="${2:-}"
need=""
have() { command -v "$1" >/dev/null 2>&1 || [ -x "/usr/sbin/$1" ] || [ -x "/sbin/$1" ]; }
venv=yes
"$python" -c "import ensurepip, venv" 2>/dev/null || venv=""
# Debian's own python3 gets its venv module from python3-venv; another python, from its maker.
if [ -z "$venv" ] && [ "$(command -v "$python")" = /usr/bin/python3 ]; then
    need="$need python3-venv"
fi
have setpriv || need="$need util-linux"
have prlimit || need="$need util-linux"
have bwrap || need="$need bubblewrap"
have slirp4netns || need="$need slirp4netns"
have ip || need="$need iproute2"
ls /usr/lib/*/faketime/libfaketime.so.1 >/dev/null 2>&1 || need="$need libfaketime"
[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need="$need fonts-dejavu-core"
if [ "$(id -u)" -eq 0 ] && [ -n "$need" ]; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends $need >/dev/null
    "$python" -c "import ensurepip, venv" 2>/dev/null && venv=yes
fi
if [ -z "$venv" ]; then
    echo "robotide's virtualenv needs $python's venv module, which is not installed:" \
        "as root, apt-get install python3-venv (or make run as root, which does)." >&2
    exit 1
fi
[ "$(id -u)" -eq 0 ] || [ "$quiet" = --quiet ] && exit 0
# Three lines: `make run` says little, and this is the one thing an ordinary user should know.
cat >&2 <<MSG
robotide: running as $(id -un), not root: programs run in a rootless box (user namespaces), with
per-process limits unless your session delegates a cgroup; the robot's page says what is in
force. For more, 'make run' as root${need:+ (it installs:$need)}.
MSG
