#!/bin/sh
# What pip needs from the machine to build the venv: python-ldap (django-auth-ldap's, for
# directory sign-in) has no binary wheel and compiles against OpenLDAP's and Cyrus SASL's
# headers. From Debian's archive, installed only when missing; as an ordinary user, says what
# to install.
set -eu
need=""
[ -e /usr/include/ldap.h ] || need="$need libldap2-dev"
[ -e /usr/include/sasl/sasl.h ] || need="$need libsasl2-dev"
command -v gcc >/dev/null 2>&1 || need="$need gcc"
python3 -c "import sysconfig, os, sys; sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h')))" \
    || need="$need python3-dev"
[ -n "$need" ] || exit 0
if [ "$(id -u)" -ne 0 ]; then
    echo "missing system packages to build python-ldap:$need (run as root, or install them)" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends $need >/dev/null
