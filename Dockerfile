FROM python:3.11-slim-bookworm
# util-linux: setpriv and prlimit; bubblewrap: the runs' box; slirp4netns and iproute2: network
# 'full'; libfaketime: a sim's runs faster than real time;
# the languages programs are written in, and what their clients use; espeak-ng and ffmpeg:
# speech and cameras for programs; fonts-dejavu-core: the words on the sim's pictures (accents);
# OpenLDAP's and SASL's headers and gcc: python-ldap (directory
# sign-in) has no binary wheel and is compiled by pip.
RUN apt-get update && apt-get install -y --no-install-recommends \
        util-linux bash bubblewrap slirp4netns iproute2 libfaketime \
        perl ruby lua5.4 lua-socket tcl tcllib nodejs \
        espeak-ng ffmpeg fonts-dejavu-core \
        libldap2-dev libsasl2-dev gcc \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY . /app
# Editable: the templates/ folder is read from the source tree.
RUN pip install --no-cache-dir -e "/app[ldap]"
ENV ROBOTIDE_DATA=/data
EXPOSE 8000
CMD ["robotide", "up", "--bind", "0.0.0.0:8000"]
