#!/bin/sh
# What runs need from the machine, for `make run`. As root: bubblewrap (the runs' box) and
# slirp4netns (the NAT of network 'full') from Debian's archive, installed when missing. As an
# ordinary user runs are boxed with what every Debian machine has (util-linux's unshare and
# python3); this says what would give them more, and goes on.
set -eu
need=""
have() { command -v "$1" >/dev/null 2>&1 || [ -x "/usr/sbin/$1" ] || [ -x "/sbin/$1" ]; }
have setpriv || need="$need util-linux"
have prlimit || need="$need util-linux"
have bwrap || need="$need bubblewrap"
have slirp4netns || need="$need slirp4netns"
if [ "$(id -u)" -eq 0 ]; then
    [ -n "$need" ] || exit 0
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends $need >/dev/null
    exit 0
fi
cat >&2 <<MSG
robotide runs as $(id -un), not root: programs run in a rootless box (user namespaces, from
util-linux and python3), with per-process limits instead of a cgroup unless your session
delegates one, and without network 'full'. The robot's page says what is in force. For more,
run 'make run' as root${need:+ (it installs:$need)}.
MSG
