FROM python:3.11-slim-bookworm
# util-linux: setpriv and prlimit for the launcher; bash for shell programs.
RUN apt-get update && apt-get install -y --no-install-recommends util-linux bash \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY . /app
RUN pip install --no-cache-dir /app
ENV ROBOTIDE_DATA=/data
EXPOSE 8000
CMD ["robotide", "up", "--bind", "0.0.0.0:8000"]
