#!/bin/sh
# What the tests need from the machine, from Debian's archive, installed only when missing:
# Chromium (browser tests), util-linux (setpriv, prlimit, unshare), bubblewrap and slirp4netns
# (the runs' box and the NAT of network 'full'), the languages' interpreters, PostgreSQL and Redis (fleet mode), started
# if they are not running, espeak-ng and ffmpeg (speech and cameras for programs), OpenLDAP's
# slapd and ldap-utils (directory sign-in), libfaketime (a sim's runs faster than real time),
# fonts-dejavu-core (the words on the sim's pictures, accents included).
set -eu
need=""
have() { command -v "$1" >/dev/null 2>&1 || [ -x "/usr/sbin/$1" ] || [ -x "/sbin/$1" ]; }
have chromium || need="$need chromium"
have setpriv || need="$need util-linux"
have prlimit || need="$need util-linux"
have bwrap || need="$need bubblewrap"
have slirp4netns || need="$need slirp4netns"
ls /usr/lib/*/faketime/libfaketime.so.1 >/dev/null 2>&1 || need="$need libfaketime"
[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ] || need="$need fonts-dejavu-core"
[ -x /usr/bin/python3 ] || need="$need python3"
/usr/bin/python3 -c "import ensurepip" 2>/dev/null || need="$need python3-venv"  # make run's .venv
# The languages programs are written in (programs/languages.py) and what their clients use.
have perl || need="$need perl"
have ruby || need="$need ruby"
have lua5.4 || need="$need lua5.4"
[ -e /usr/share/lua/5.4/socket.lua ] || need="$need lua-socket"
have tclsh || need="$need tcl"
ls -d /usr/share/tcltk/tcllib* >/dev/null 2>&1 || need="$need tcllib"
have node || need="$need nodejs"
have npm || need="$need npm"  # the OpenID Connect test provider (tests/oidc/)
have redis-server || need="$need redis-server"
have pg_ctlcluster || need="$need postgresql"
# Host services for programs (say, the camera) and their tests.
have espeak-ng || need="$need espeak-ng"
have ffmpeg || need="$need ffmpeg"
# A real directory for the LDAP sign-in tests (tests/test_ldap.py starts its own slapd).
have slapd || need="$need slapd"
have ldapadd || need="$need ldap-utils"
# GNU gettext for the translation catalogs' test (tests/test_i18n.py runs makemessages).
have msgfmt || need="$need gettext"
if [ -n "$need" ]; then
    if [ "$(id -u)" -ne 0 ]; then
        echo "missing system packages:$need (run as root, or install them)" >&2
        exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends $need >/dev/null
fi

# pymavlink for the programs of the MAVLink gateway's tests.
"$(dirname "$0")/install-program-libs.sh"

# node's oidc-provider for the OpenID Connect sign-in tests, at the versions its lock file pins.
if [ "${1:-}" != "--packages-only" ]; then
    (cd "$(dirname "$0")/../tests/oidc" && npm ci --no-audit --no-fund --loglevel=error)
fi

# The services, as this kind of machine starts them, if they are down (not for `make fleet`,
# which runs servers of its own: --packages-only).
[ "${1:-}" = "--packages-only" ] && exit 0
if ! redis-cli -h 127.0.0.1 ping >/dev/null 2>&1; then
    mkdir -p /var/lib/redis /var/log/redis
    redis-server --daemonize yes --bind 127.0.0.1 -::1 --port 6379 --save "" \
        --appendonly no --dir /var/lib/redis --logfile /var/log/redis/ci.log
fi
if ! pg_isready -h 127.0.0.1 -p 5432 >/dev/null 2>&1; then
    version=$(ls /etc/postgresql | sort -n | tail -1)
    pg_ctlcluster --skip-systemctl-redirect "$version" main start
fi
for i in $(seq 1 30); do
    redis-cli -h 127.0.0.1 ping >/dev/null 2>&1 && pg_isready -h 127.0.0.1 -p 5432 >/dev/null 2>&1 && exit 0
    sleep 1
done
echo "Redis or PostgreSQL did not come up on 127.0.0.1" >&2
exit 1
