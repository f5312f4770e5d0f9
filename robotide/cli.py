"""The robotide command.

robotide up [--bind HOST:PORT]   migrate, set up, serve (web + agents in one process, unless
                                 REDIS_URL is set: then the web tier only)
robotide agent NAME              run one robot's agent (fleet mode)
robotide token USERNAME          print a new API token for a user
robotide robots detect [--json]  list serial ports and USB devices that look like robots
robotide manage ...              Django's manage.py commands
"""

import argparse
import asyncio
import contextlib
import json
import os
import secrets
import signal
import sys

import uvicorn

DEFAULT_BIND = "127.0.0.1:8000"


def setup_django() -> None:
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "robotide.settings")
    import django

    django.setup()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="robotide", description="Web-based robot programming.")
    commands = parser.add_subparsers(dest="command", required=True)
    up = commands.add_parser("up", help="set up and serve the appliance")
    up.add_argument("--bind", default=os.environ.get("ROBOTIDE_BIND", DEFAULT_BIND))
    agent = commands.add_parser("agent", help="run one robot's agent")
    agent.add_argument("name")
    token = commands.add_parser("token", help="print a new API token for a user")
    token.add_argument("username")
    token.add_argument("--name", default="command line")
    robots = commands.add_parser("robots", help="robot hardware on this computer")
    robot_commands = robots.add_subparsers(dest="robots_command", required=True)
    detect = robot_commands.add_parser("detect", help="list devices that look like robots")
    detect.add_argument("--json", action="store_true", help="print JSON lines")
    commands.add_parser("manage", help="Django management commands", add_help=False)
    args, rest = parser.parse_known_args(argv)
    if args.command == "robots":
        if rest:
            parser.error(f"unrecognized arguments: {' '.join(rest)}")
        return cmd_detect(args)
    if args.command != "manage" and rest:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    # What the server writes is its own; run accounts get only what is opened to them.
    os.umask(0o077)
    setup_django()
    return {"up": cmd_up, "agent": cmd_agent, "token": cmd_token, "manage": cmd_manage}[
        args.command
    ](args, rest)


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


def cmd_up(args, rest) -> int:
    from django.conf import settings
    from django.core.management import call_command

    host, port = parse_bind(args.bind)
    call_command("migrate", interactive=False, verbosity=0)
    protect_data_dir()
    ensure_admin()
    ensure_sim_robot()
    embedded = not settings.REDIS_URL
    mode = "embedded: web and robot agents in this process" if embedded else "web tier only"
    print(f"robotide serving on http://{host}:{port}/ ({mode})", flush=True)
    asyncio.run(serve(host, port, with_agents=embedded))
    return 0


def parse_bind(bind: str) -> tuple[str, int]:
    host, sep, port = bind.rpartition(":")
    if not sep or not port.isdigit():
        raise SystemExit(f"robotide: --bind must be HOST:PORT, not {bind!r}")
    return host.strip("[]") or "127.0.0.1", int(port)


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
        print("(shown once; change it at /accounts/password/)", flush=True)


def ensure_sim_robot() -> None:
    from robots.models import Robot

    Robot.objects.get_or_create(
        name="sim", defaults={"url": "sim://", "description": "Simulated robot"}
    )


async def serve(host: str, port: int, with_agents: bool) -> None:
    from django.conf import settings

    from robots import bus
    from robots.agent import AgentManager

    config = uvicorn.Config(
        "robotide.asgi:application",
        host=host,
        port=port,
        lifespan="off",
        ws="websockets-sansio",
        log_level="warning",
        access_log=False,
        # Forwarded-for headers only from a proxy we are told of: a local program could
        # otherwise pose as any address (and dodge the sign-in throttle).
        proxy_headers=settings.BEHIND_PROXY,
    )
    server = _Server(config)
    bus.serve_on(asyncio.get_running_loop())
    manager = AgentManager() if with_agents else None
    if manager is not None:
        await manager.start()
    try:
        await server.serve()
    finally:
        if manager is not None:
            await manager.shutdown()


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

    async def shutdown(self, sockets=None):
        from robots.camera import close_streams

        await close_streams()  # camera streams never end by themselves; uvicorn waits for them
        await super().shutdown(sockets)


def cmd_agent(args, rest) -> int:
    from robots.models import Robot

    if not Robot.objects.filter(name=args.name).exists():
        print(f"robotide: no robot named {args.name!r}; add it in the admin or POST /api/robots",
              file=sys.stderr)  # fmt: skip
        return 2
    protect_data_dir()
    asyncio.run(run_agent(args.name))
    return 0


async def run_agent(name: str) -> None:
    from robots.agent import RobotAgent

    agent = RobotAgent(name)
    task = asyncio.create_task(agent.serve())
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, task.cancel)
    print(f"robotide agent for robot {name!r} running", flush=True)
    with contextlib.suppress(asyncio.CancelledError):
        await task


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


def cmd_manage(args, rest) -> int:
    from django.core.management import execute_from_command_line

    execute_from_command_line(["robotide manage", *rest])
    return 0


if __name__ == "__main__":
    sys.exit(main())
