"""The robotide command.

robotide up [--bind HOST:PORT]   migrate, set up, serve (web + agents in one process, unless
                                 REDIS_URL is set: then the web tier only)
robotide robots online [--here] [NAME...]
                                 exit 0 if the robots' agents beat lately (a health check)
robotide agent NAME... [--url URL] [--sim N] [--personal-sims] [--no-standby]
                                 run robots' agents (fleet mode): those named (one registered
                                 with --url if new) and N simulated ones, sim-1 to sim-N; one
                                 process each: a second stands by (or exits) while one serves
robotide token USERNAME          print a new API token for a user
robotide robots detect [--json]  list serial ports and USB devices that look like robots
robotide export USERNAME [-o FILE]
                                 a user's programs as a zip of plain files and a manifest
                                 (to standard output, unless that is a terminal)
robotide import USERNAME FILE [--replace]
                                 programs from such a zip (FILE - : standard input)
robotide user add NAME [--staff] [--group G] [--password-stdin]
                                 create an account; its password is printed once if generated
                                 (else from standard input or ROBOTIDE_USER_PASSWORD)
robotide user password NAME [--password-stdin | --generate]
                                 set a new password (asked twice, read from standard input,
                                 or generated and printed once): a lost admin password too
robotide route VEHICLE --to ENDPOINT [--to ...]
                                 the MAVLink router alone, no web application: VEHICLE is
                                 DEVICE[:BAUD], udp:HOST:PORT (listened on) or tcp:HOST:PORT;
                                 each ENDPOINT udp:HOST:PORT (sent to), udpin:, tcp: or tcpin:;
                                 --tlog FILE records every routed frame there
robotide replay FILE --to ENDPOINT [--to ...] [--speed X | --fast] [--loop]
                                 a .tlog's frames sent to the endpoints, with their timing
robotide manage ...              Django's manage.py commands
"""

import argparse
import asyncio
import contextlib
import errno
import gc
import getpass
import json
import os
import resource
import secrets
import shutil
import signal
import socket
import sys
import threading

import uvicorn

from runbox import delegate, oom

DEFAULT_BIND = "127.0.0.1:8000"


def setup_django() -> None:
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "robotide.settings")
    import django

    django.setup()


def build_parser() -> argparse.ArgumentParser:
    """Every command and option; main() runs them (the compose file's check parses with it)."""
    parser = argparse.ArgumentParser(prog="robotide", description="Web-based robot programming.")
    commands = parser.add_subparsers(dest="command", required=True)
    up = commands.add_parser("up", help="set up and serve the appliance")
    up.add_argument("--bind", default=os.environ.get("ROBOTIDE_BIND", DEFAULT_BIND))
    up.add_argument(
        "--workers", type=int, default=int(os.environ.get("ROBOTIDE_WEB_WORKERS") or 1),
        help="web server processes (fleet mode: REDIS_URL set); default ROBOTIDE_WEB_WORKERS or 1",
    )  # fmt: skip
    agent = commands.add_parser("agent", help="run robots' agents (fleet mode)")
    agent.add_argument("names", nargs="*", metavar="NAME", help="the robots to serve")
    agent.add_argument("--url", help="register NAME with this driver URL if it is not known")
    agent.add_argument(
        "--sim", type=int, default=int(os.environ.get("ROBOTIDE_SIM_ROBOTS") or 0), metavar="N",
        help="also serve N simulated robots, sim-1 to sim-N (registered if new); "
        "default ROBOTIDE_SIM_ROBOTS or 0",
    )  # fmt: skip
    agent.add_argument(
        "--personal-sims", action="store_true",
        help="also serve users' personal sims (made and removed while it runs) and remove "
        "idle ones: one such agent process per fleet",
    )  # fmt: skip
    agent.add_argument(
        "--no-standby", dest="standby", action="store_false",
        help="exit (code 3) if another process serves one of these robots (or the personal "
        "sims), instead of standing by to take over when it ends (3 too if its lock is lost)",
    )  # fmt: skip
    token = commands.add_parser("token", help="print a new API token for a user")
    token.add_argument("username")
    token.add_argument("--name", default="command line")
    robots = commands.add_parser("robots", help="robot hardware on this computer")
    robot_commands = robots.add_subparsers(dest="robots_command", required=True)
    detect = robot_commands.add_parser("detect", help="list devices that look like robots")
    detect.add_argument("--json", action="store_true", help="print JSON lines")
    online = robot_commands.add_parser(
        "online", help="exit 0 if these robots' agents beat lately (a health check)"
    )
    online.add_argument("names", nargs="*", metavar="NAME")
    online.add_argument("--here", action="store_true", help="the robots served from this host")
    export = commands.add_parser("export", help="a user's programs as a zip of plain files")
    export.add_argument("username")
    export.add_argument(
        "-o", "--output", help="the zip to write, - for standard output (the default unless "
        "that is a terminal: then ./robotide-USER-DATE.zip)",
    )  # fmt: skip
    import_ = commands.add_parser("import", help="programs from a zip, as export makes")
    import_.add_argument("username")
    import_.add_argument("file", help="the zip, - for standard input")
    import_.add_argument(
        "--replace", action="store_true",
        help="a program of the same name gets a new revision instead of a copy",
    )  # fmt: skip
    user = commands.add_parser("user", help="accounts")
    user_commands = user.add_subparsers(dest="user_command", required=True)
    user_add = user_commands.add_parser(
        "add", help="create an account; its password is printed once unless given"
    )
    user_add.add_argument("name")
    user_add.add_argument("--staff", action="store_true", help="a teacher or administrator")
    user_add.add_argument("--group", help="add to this group (a class), created if need be")
    user_add.add_argument(
        "--password-stdin", action="store_true",
        help="read the password from standard input (or set ROBOTIDE_USER_PASSWORD)",
    )  # fmt: skip
    user_password = user_commands.add_parser(
        "password", help="set a new password (asked twice unless read or generated)"
    )
    user_password.add_argument("name")
    how = user_password.add_mutually_exclusive_group()
    how.add_argument("--password-stdin", action="store_true", help="read it from standard input")
    how.add_argument("--generate", action="store_true", help="make one up and print it once")
    route = commands.add_parser("route", help="the MAVLink router alone (no web application)")
    route.add_argument("vehicle", help="DEVICE[:BAUD], udp:HOST:PORT or tcp:HOST:PORT")
    route.add_argument(
        "--to", action="append", default=[], metavar="ENDPOINT",
        help="udp:HOST:PORT (client), udpin:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT",
    )  # fmt: skip
    route.add_argument("--baud", type=int, default=115200, help="when VEHICLE names none")
    route.add_argument("--stats", type=float, default=0, help="print stats every N s")
    route.add_argument("--tlog", metavar="FILE", help="record every routed frame to this .tlog")
    replay = commands.add_parser("replay", help="send a .tlog's frames to MAVLink endpoints")
    replay.add_argument("file", help="the .tlog")
    replay.add_argument(
        "--to", action="append", required=True, metavar="ENDPOINT",
        help="udp:HOST:PORT (client), udpin:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT",
    )  # fmt: skip
    replay.add_argument("--speed", type=float, default=1.0, help="times the recorded rate; 0: "
                        "as fast as the endpoints take them")  # fmt: skip
    replay.add_argument("--fast", action="store_const", const=0.0, dest="speed",
                        help="the same as --speed 0")  # fmt: skip
    replay.add_argument("--loop", action="store_true", help="from the start again at the end")
    commands.add_parser("manage", help="Django management commands", add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    if args.command == "robots" and args.robots_command == "detect":
        if rest:
            parser.error(f"unrecognized arguments: {' '.join(rest)}")
        return cmd_detect(args)
    if args.command == "route":
        if rest:
            parser.error(f"unrecognized arguments: {' '.join(rest)}")
        return cmd_route(args)
    if args.command == "replay":
        if rest:
            parser.error(f"unrecognized arguments: {' '.join(rest)}")
        return cmd_replay(args)
    if args.command != "manage" and rest:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    # What the server writes is its own; run accounts get only what is opened to them.
    os.umask(0o077)
    if args.command in ("up", "agent"):
        # Not root: in a cgroup the user's systemd delegates, if it can, so runs have theirs.
        if (scoped := delegate.delegated_command()) is not None:
            os.execve(scoped[0], scoped, {**os.environ, delegate.DELEGATED: "1"})
        open_files_as_allowed()
        # Out of memory, the kernel kills a run's process, never the server or an agent first.
        oom.protect_this_process()
    setup_django()
    return {
        "up": cmd_up,
        "agent": cmd_agent,
        "robots": cmd_online,
        "token": cmd_token,
        "export": cmd_export,
        "import": cmd_import,
        "user": cmd_user,
        "manage": cmd_manage,
    }[args.command](args, rest)


def cmd_detect(args) -> int:
    """No Django and no umask change: it only reads what the kernel says."""
    from rhal.detect import detect

    findings = detect()
    for finding in findings:
        if args.json:
            print(json.dumps(finding.as_dict()))
        else:
            guess = "" if finding.sure else "  (a guess: check it)"
            print(f"{finding.device}\t{finding.looks_like}\n    {finding.url}{guess}")
    if not findings and not args.json:
        print("No device here looks like a robot this version drives.", file=sys.stderr)
    return 0


def cmd_route(args) -> int:
    """No Django: the router alone, until SIGTERM or SIGINT."""
    from gateway.router import Router, endpoint_from_spec

    try:
        endpoints = [endpoint_from_spec(args.vehicle, vehicle=True, baud=args.baud)]
        endpoints += [endpoint_from_spec(spec) for spec in args.to]
    except ValueError as exc:
        print(f"robotide route: {exc}", file=sys.stderr)
        return 2
    recorder = None
    if args.tlog:
        from gateway.tlog import TlogRecorder

        recorder = TlogRecorder(args.tlog)
        try:
            recorder.start()
        except OSError as exc:
            print(f"robotide route: cannot write {args.tlog}: {exc.strerror}", file=sys.stderr)
            return 2

    async def run() -> int:
        router = Router()
        if recorder:
            router.taps.append(recorder)
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop.set)
        try:
            for endpoint in endpoints:
                try:
                    await router.add(endpoint)
                except (OSError, ValueError) as exc:
                    print(f"robotide route: {endpoint.name}: {exc}", file=sys.stderr)
                    return 1
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), args.stats or None)
                if args.stats:
                    for row in router.stats():
                        print(json.dumps(row), file=sys.stderr)
                    if recorder:
                        print(json.dumps({"tlog": recorder.as_dict()}), file=sys.stderr)
        finally:
            await router.close()
            if recorder:
                await asyncio.to_thread(recorder.close)
        return 0

    return asyncio.run(run())


def cmd_replay(args) -> int:
    """No Django: a .tlog to endpoints, until its end (or with --loop, SIGTERM or SIGINT)."""
    import time

    from gateway.router import endpoint_from_spec
    from gateway.tlog import check_tlog, replay

    if args.speed < 0:
        print("robotide replay: --speed must be 0 or more", file=sys.stderr)
        return 2
    try:
        check_tlog(args.file)
        endpoints = [endpoint_from_spec(spec) for spec in args.to]
    except OSError as exc:
        print(f"robotide replay: cannot read {args.file}: {exc.strerror}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"robotide replay: {exc}", file=sys.stderr)
        return 2

    async def run() -> int:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop.set)
        return await replay(args.file, endpoints, speed=args.speed, loop=args.loop, stop=stop)

    began = time.monotonic()
    try:
        frames = asyncio.run(run())
    except (OSError, ValueError) as exc:
        print(f"robotide replay: {exc}", file=sys.stderr)
        return 2
    drops = sum(endpoint.stats.drops for endpoint in endpoints)
    dropped = f", {drops} not sent (an endpoint down or behind)" if drops else ""
    print(f"replayed {frames} frames in {time.monotonic() - began:.1f} s{dropped}")
    return 0


def cmd_up(args, rest) -> int:
    from django.conf import settings
    from django.core.management import call_command

    host, port = parse_bind(args.bind)
    # Bound before anything is set up or said: a busy port is told as such, not after
    # "serving on" as a bare errno from deep in the server.
    sock = listening_socket(host, port)
    call_command("migrate", interactive=False, verbosity=0)
    protect_data_dir()
    ensure_admin()
    ensure_sim_robot()
    embedded = not settings.REDIS_URL
    if args.workers < 1 or (embedded and args.workers > 1):
        raise SystemExit(
            "robotide: --workers must be 1 in embedded mode (the agents live in the one web "
            "process); set REDIS_URL and run the agents as `robotide agent NAME` for more"
        )
    if not embedded:
        call_command("collectstatic", interactive=False, verbosity=0)
    mode = "embedded: web and robot agents in this process" if embedded else "web tier only"
    workers = f", {args.workers} workers" if args.workers > 1 else ""
    print(f"robotide serving on http://{host}:{port}/ ({mode}{workers})", flush=True)
    if args.workers > 1:
        serve_workers(host, port, args.workers, sock)
    else:
        asyncio.run(serve(host, port, sock, with_agents=embedded))
    return 0


def open_files_as_allowed(most: int = 65536) -> None:
    """The server's open-files limit raised to what the system allows (systemd's soft 1024 is
    for select(), which the server does not use): every connection of every run and viewer is
    one. Runs get their own limit (RUN_DEFAULTS' open_files) in their box."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = most if hard == resource.RLIM_INFINITY else min(hard, most)
    if soft != resource.RLIM_INFINITY and soft < wanted:
        resource.setrlimit(resource.RLIMIT_NOFILE, (wanted, hard))


def parse_bind(bind: str) -> tuple[str, int]:
    host, sep, port = bind.rpartition(":")
    if not sep or not port.isdigit():
        raise SystemExit(f"robotide: --bind must be HOST:PORT, not {bind!r}")
    return host.strip("[]") or "127.0.0.1", int(port)


def listening_socket(host: str, port: int) -> socket.socket:
    """The server's socket, bound (uvicorn listens on it): as uvicorn's Config.bind_socket,
    but what stops it is said in words, with the way to another port, and no traceback."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        # Listening at once: two servers started together both bind (SO_REUSEADDR), one listens.
        sock.listen(2048)  # uvicorn's backlog; it listens again with its own
    except OSError as exc:
        sock.close()
        raise SystemExit(bind_refused(host, port, exc)) from None
    # Linux copies it to the accepted connections: uvicorn's worker processes never have asyncio
    # set it on theirs, and each keep-alive response would wait ~40 ms for the delayed ACK.
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock  # not inheritable: no program run may get the server's socket


def bind_refused(host: str, port: int, exc: OSError) -> str:
    other = f"{host}:{port + 1}" if ":" not in host else f"[{host}]:{port + 1}"
    choose = f"Choose another: make run BIND={other} (or robotide up --bind {other})"
    if exc.errno == errno.EADDRINUSE:
        return (
            f"robotide: port {port} on {host} is already in use (another robotide, or another "
            f"program?).\n{choose}"
        )
    if exc.errno == errno.EACCES:
        return (
            f"robotide: may not listen on port {port} on {host} (below 1024: root only).\n{choose}"
        )
    return f"robotide: cannot listen on {host}:{port}: {exc.strerror}.\n{choose}"


def protect_data_dir() -> None:
    """Run accounts may pass through the data folder to their own, and read nothing in it."""
    from django.conf import settings

    settings.RUNS_DIR.mkdir(exist_ok=True)
    for folder in (settings.DATA_DIR, settings.RUNS_DIR):
        folder.chmod(0o711)
    for path in settings.DATA_DIR.glob("robotide.sqlite3*"):
        path.chmod(0o600)


def ensure_admin() -> None:
    from django.contrib.auth import get_user_model

    User = get_user_model()
    if User.objects.filter(is_superuser=True).exists():
        return
    username = os.environ.get("ROBOTIDE_ADMIN_USER", "admin")
    password = os.environ.get("ROBOTIDE_ADMIN_PASSWORD")
    User.objects.create_superuser(
        username, "", password or (generated := secrets.token_urlsafe(12))
    )
    if not password:
        print(f"Created the admin account: user {username!r}, password {generated!r}", flush=True)
        print(
            "(shown once; change it at /accounts/password/, or set a new one with: "
            f"{robotide_command()} user password {username})",
            flush=True,
        )


def robotide_command() -> str:
    """How to call this command again: `robotide` where that finds it, else the path it was
    started as (`make run` starts .venv/bin/robotide, which is on no PATH)."""
    started = sys.argv[0]
    found = shutil.which("robotide")
    if os.path.basename(started) != "robotide" or (
        found and os.path.realpath(found) == os.path.realpath(started)
    ):
        return "robotide"
    return started


def ensure_sim_robot() -> None:
    from robots.models import Robot

    Robot.objects.get_or_create(
        name="sim", defaults={"url": "sim://", "description": "Simulated robot"}
    )


def server_options() -> dict:
    from django.conf import settings

    return {
        "lifespan": "off",
        "ws": "websockets-sansio",
        "log_level": "warning",
        "access_log": False,
        # Forwarded-for headers only from a proxy we are told of: a local program could
        # otherwise pose as any address (and dodge the sign-in throttle).
        "proxy_headers": settings.BEHIND_PROXY,
        # Camera streams never end by themselves: stop waiting for them after a while.
        "timeout_graceful_shutdown": 5,
    }


def serve_workers(host: str, port: int, workers: int, sock: socket.socket) -> None:
    """Fleet mode's web tier: uvicorn's worker processes, which it restarts if one dies; here
    the watch on the agents' heartbeats (robots.presence), in a thread of its own."""
    from uvicorn.supervisors import Multiprocess

    from robots import presence

    watcher = threading.Thread(target=asyncio.run, args=(presence.watch(),), daemon=True)
    watcher.start()
    config = uvicorn.Config(
        "robotide.asgi:application", host=host, port=port, workers=workers, **server_options()
    )
    sock.set_inheritable(True)  # uvicorn's worker processes are spawned with it
    Multiprocess(config, sockets=[sock]).run()


async def serve(host: str, port: int, sock: socket.socket, with_agents: bool) -> None:
    from robots import bus, presence
    from robots.agent import AgentManager

    config = uvicorn.Config("robotide.asgi:application", host=host, port=port, **server_options())
    server = _Server(config)
    bus.serve_on(asyncio.get_running_loop())
    manager = AgentManager() if with_agents else None
    watcher = None
    if manager is not None:
        await manager.start()
    else:  # fleet mode: the agents are elsewhere, and may go silent
        watcher = asyncio.create_task(presence.watch(), name="presence")
    try:
        await server.serve(sockets=[sock])
    finally:
        if manager is not None:
            await manager.shutdown()
        if watcher is not None:
            watcher.cancel()


class _Server(uvicorn.Server):
    """uvicorn's server, with signals handled on our loop so the agents shut down cleanly
    (uvicorn's own handlers re-raise the signal once it has stopped, killing the process)."""

    @contextlib.contextmanager
    def capture_signals(self):
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, self.handle_exit, sig, None)
        try:
            yield
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)

    async def startup(self, sockets=None):
        await super().startup(sockets)
        settle_heap()

    async def shutdown(self, sockets=None):
        from robots.camera import close_streams

        await close_streams()  # camera streams never end by themselves; uvicorn waits for them
        await super().shutdown(sockets)


def settle_heap() -> None:
    """Once started, what the process has made so far (Django, the apps, their modules: most of
    its objects) is left out of the garbage collector's full passes. With them, a full pass
    under use took 99-107 ms here, every few seconds, and stalled the one event loop that
    answers the robot's emergency stop, hand driving and every page; without, 24-25 ms."""
    gc.collect()
    gc.freeze()


def cmd_agent(args, rest) -> int:
    from robots.models import Robot

    names = list(args.names)
    if args.url and len(names) != 1:
        print("robotide agent: --url registers one robot: give its NAME", file=sys.stderr)
        return 2
    for n in range(1, args.sim + 1):
        Robot.objects.get_or_create(
            name=f"sim-{n}", defaults={"url": "sim://", "description": "Simulated robot"}
        )
        names.append(f"sim-{n}")
    if args.url:
        register_robot(names[0], args.url)
    missing = [n for n in names if not Robot.objects.filter(name=n).exists()]
    if missing or not (names or args.personal_sims):
        print(f"robotide agent: no robot named {', '.join(map(repr, missing)) or 'given'};"
              " add it in the admin, POST /api/robots, or give --url", file=sys.stderr)  # fmt: skip
        return 2
    protect_data_dir()
    served = asyncio.run(run_agents(names, personal_sims=args.personal_sims, standby=args.standby))
    return 0 if served else 3


def cmd_online(args, rest) -> int:
    from robots.models import Robot

    robots = Robot.objects.filter(reaped__isnull=True)  # not removed personal sims
    if args.here:
        robots = robots.filter(agent_host=socket.gethostname())
    if args.names:
        robots = robots.filter(name__in=args.names)
    found = {robot.name: robot for robot in robots}
    asked = args.names or list(found)
    if not asked:
        print("robotide robots online: no robot served here", file=sys.stderr)
        return 1
    offline = [name for name in asked if name not in found or not found[name].online]
    for name in asked:
        robot = found.get(name)
        seen = robot.last_seen.isoformat() if robot and robot.last_seen else "never"
        state = "online" if name not in offline else "offline"
        print(f"{name}: {state} (last seen {seen})")
    return 1 if offline else 0


def register_robot(name: str, url: str) -> None:
    """A robot that comes with its agent: known from now on, with this URL if it is new."""
    from robots.driver_settings import known_driver
    from robots.models import Robot

    try:
        known_driver(url)
    except ValueError as exc:
        raise SystemExit(f"robotide agent: {exc}") from None
    robot, created = Robot.objects.get_or_create(name=name, defaults={"url": url})
    if not created and robot.url != url:
        print(f"robotide agent: robot {name!r} is known with {robot.url!r}; serving that"
              " (change it on its page)", file=sys.stderr)  # fmt: skip


async def run_agents(names: list[str], personal_sims: bool = False, standby: bool = True) -> bool:
    """Each robot's agent, until SIGTERM or SIGINT; one that fails is started again. With
    ``personal_sims``, the personal sims' too, and their reaper (robots.sims). Each robot (and
    the personal sims) only once its lock is this process's (robots.agent_lock): while another
    process serves it, this one stands by, or, not ``standby``, returns False at once (and
    False if its locks' database connection failed: another may serve them now)."""
    from robots import agent_lock
    from robots.agent import AgentManager

    def said(text: str) -> None:
        print(f"robotide agent: {text}", file=sys.stderr, flush=True)

    manager = AgentManager()
    parts = [*names, *([agent_lock.PERSONAL_SIMS] if personal_sims else [])]
    locks = agent_lock.agent_locks()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)

    async def serve(part: str) -> None:
        await agent_lock.take(locks, part, standby, said)
        if part == agent_lock.PERSONAL_SIMS:
            await manager.start(personal_only=True)
        else:
            manager.start_agent(part)

    async def serve_all() -> None:
        await asyncio.gather(*(serve(part) for part in parts))
        settle_heap()
        print(f"robotide agent for {', '.join(parts)} running", flush=True)

    def ended(task: asyncio.Task) -> None:
        if not task.cancelled() and task.exception() is not None:
            stop.set()

    serving = asyncio.create_task(serve_all())
    watching = asyncio.create_task(locks.watch())
    for task in (serving, watching):
        task.add_done_callback(ended)
    try:
        await stop.wait()
    finally:
        for task in (serving, watching):
            task.cancel()
        outcomes = await asyncio.gather(serving, watching, return_exceptions=True)
        await manager.shutdown()
        await locks.close()  # after its agents ended: a standby takes over only then
    failed = [exc for exc in outcomes if isinstance(exc, Exception)]
    for exc in failed:
        if isinstance(exc, agent_lock.LockLost):
            said(f"{exc}; stopped, so that no two processes serve the same robots")
        elif not isinstance(exc, agent_lock.Refused):
            raise exc
    return not failed


def cmd_token(args, rest) -> int:
    from django.contrib.auth import get_user_model

    from robotide.models import ApiToken

    try:
        user = get_user_model().objects.get(username=args.username)
    except get_user_model().DoesNotExist:
        print(f"robotide: no user named {args.username!r}", file=sys.stderr)
        return 2
    _, token = ApiToken.issue(user, args.name)
    print(token)
    return 0


def _user_named(username: str):
    from django.contrib.auth import get_user_model

    try:
        return get_user_model().objects.get(username=username)
    except get_user_model().DoesNotExist:
        print(f"robotide: no user named {username!r}", file=sys.stderr)
        return None


def cmd_export(args, rest) -> int:
    from programs.archive import export_filename, export_zip
    from programs.models import Program

    user = _user_named(args.username)
    if user is None:
        return 2
    programs = Program.objects.filter(owner=user)
    data = export_zip(programs)
    output = args.output or ("-" if not sys.stdout.isatty() else export_filename(user))
    if output == "-":
        try:
            sys.stdout.buffer.write(data)
            sys.stdout.buffer.flush()
        except BrokenPipeError:  # the reader went away (`| head`): no traceback for that
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 1
        output = "standard output"
    else:
        try:
            with open(output, "wb") as out:
                out.write(data)
        except OSError as exc:
            print(f"robotide: cannot write {output}: {exc.strerror}", file=sys.stderr)
            return 1
    print(f"Exported {programs.count()} programs of {user.username} to {output}", file=sys.stderr)
    return 0


def cmd_import(args, rest) -> int:
    from programs.archive import MAX_TOTAL_BYTES, ArchiveError, import_zip

    user = _user_named(args.username)
    if user is None:
        return 2
    try:
        if args.file == "-":
            data = sys.stdin.buffer.read(MAX_TOTAL_BYTES + 1)
        else:
            with open(args.file, "rb") as zip_file:
                data = zip_file.read(MAX_TOTAL_BYTES + 1)  # more is refused: no need to read it
    except OSError as exc:
        print(f"robotide: cannot read {args.file}: {exc.strerror}", file=sys.stderr)
        return 2
    name = "standard input" if args.file == "-" else os.path.basename(args.file)
    try:
        report = import_zip(data, user, filename=name, replace=args.replace)
    except ArchiveError as exc:
        print(f"robotide: nothing imported: {exc}", file=sys.stderr)
        return 1
    for line in report.lines():
        print(line)
    print(f"{report.summary()} for {user.username}")
    return 0


def cmd_user(args, rest) -> int:
    if args.user_command == "password":
        return cmd_user_password(args)
    return cmd_user_add(args)


def cmd_user_password(args) -> int:
    from django.contrib.auth.password_validation import validate_password
    from django.core.exceptions import ValidationError

    user = _user_named(args.name)
    if user is None:
        return 2
    password = new_password(args)
    if password is None:
        return 2
    try:
        validate_password(password, user)
    except ValidationError as exc:
        print(f"robotide: password refused: {' '.join(exc.messages)}", file=sys.stderr)
        return 2
    user.set_password(password)  # its sessions elsewhere end: they were signed with the old one
    user.save(update_fields=["password"])
    if args.generate:
        print(f"New password of {user.username!r}: {password!r} (shown once)")
    else:
        print(f"New password of {user.username!r} set")
    return 0


def new_password(args) -> str | None:
    """From standard input, generated, or typed twice at the terminal; None: said why not."""
    if args.generate:
        return secrets.token_urlsafe(12)
    if args.password_stdin:
        password = sys.stdin.readline().rstrip("\r\n")
        if not password:
            print("robotide: no password on standard input", file=sys.stderr)
        return password or None
    try:
        password = getpass.getpass(f"New password of {args.name}: ")
        again = getpass.getpass("The same again: ")
    except (EOFError, KeyboardInterrupt):
        print("\nrobotide: no password set", file=sys.stderr)
        return None
    if password != again:
        print("robotide: the two passwords differ; nothing set", file=sys.stderr)
        return None
    if not password:
        print("robotide: an empty password; nothing set", file=sys.stderr)
        return None
    return password


def cmd_user_add(args) -> int:
    from django.contrib.auth import get_user_model
    from django.contrib.auth.models import Group
    from django.contrib.auth.password_validation import validate_password
    from django.core.exceptions import ValidationError
    from django.db import transaction

    User = get_user_model()
    if User.objects.filter(username=args.name).exists():
        print(f"robotide: a user named {args.name!r} exists already", file=sys.stderr)
        return 2
    try:
        User._meta.get_field("username").clean(args.name, None)
        Group._meta.get_field("name").clean(args.group or "-", None)
    except ValidationError as exc:
        print(f"robotide: {' '.join(exc.messages)}", file=sys.stderr)
        return 2
    if args.password_stdin:
        password = sys.stdin.readline().rstrip("\r\n")
        if not password:
            print("robotide: no password on standard input", file=sys.stderr)
            return 2
    else:
        password = os.environ.get("ROBOTIDE_USER_PASSWORD") or None
    generated = secrets.token_urlsafe(12) if password is None else None
    try:
        validate_password(password or generated, User(username=args.name))
    except ValidationError as exc:
        print(f"robotide: password refused: {' '.join(exc.messages)}", file=sys.stderr)
        return 2
    with transaction.atomic():
        user = User.objects.create_user(args.name, password=password or generated)
        if args.staff:
            user.is_staff = True
            user.save(update_fields=["is_staff"])
        if args.group:
            group, _ = Group.objects.get_or_create(name=args.group)
            user.groups.add(group)
    what = " (staff)" if args.staff else ""
    where = f" in group {args.group!r}" if args.group else ""
    if generated:
        print(f"Created user {args.name!r}{what}{where}, password {generated!r}")
        print("(shown once; change it at /accounts/password/)")
    else:
        print(f"Created user {args.name!r}{what}{where}")
    return 0


def cmd_manage(args, rest) -> int:
    from django.core.management import execute_from_command_line

    execute_from_command_line(["robotide manage", *rest])
    return 0


if __name__ == "__main__":
    sys.exit(main())
