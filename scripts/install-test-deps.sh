#!/bin/sh
# System packages the tests need, from Debian's archive: Chromium for the browser tests,
# util-linux for the launcher (setpriv, prlimit). Installs only what is missing.
set -eu
need=""
command -v chromium >/dev/null 2>&1 || need="$need chromium"
command -v setpriv >/dev/null 2>&1 || need="$need util-linux"
command -v prlimit >/dev/null 2>&1 || need="$need util-linux"
command -v python3 >/dev/null 2>&1 || need="$need python3"
[ -x /usr/bin/python3 ] || need="$need python3"
[ -n "$need" ] || exit 0
if [ "$(id -u)" -ne 0 ]; then
    echo "missing system packages:$need (run as root, or install them)" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends $need >/dev/null
