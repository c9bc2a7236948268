"""``drivebench serve | health | tls | simulate | hub | users | tokens | db``."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import ipaddress
import logging.config
import os
import re
import signal
import sys
import threading
from pathlib import Path

from sqlalchemy.exc import SQLAlchemyError

from drivebench import i18n, logs
from drivebench.config import settings
from drivebench.errors import DriveBenchError, InvalidValue
from drivebench.i18n import _
from drivebench.services.users.principals import Role


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def serve(args: argparse.Namespace) -> int:
    from drivebench.web import heap

    heap.hold()  # until the app has started (create_app(settle_heap=True) settles it)
    import uvicorn
    from uvicorn.config import STARTUP_FAILURE

    from drivebench.web import serving
    from drivebench.web.access import secret_key
    from drivebench.web.app import create_app
    from drivebench.web.forwarded_prefix import proxied
    from drivebench.web.https_port import HttpsPortServer
    from drivebench.web.tls import check_pair

    logging.config.dictConfig(serving.log_config(args.log_level, args.log_format))  # start-up records too
    check_pair(args.tls_cert, args.tls_key)  # before the database: a file mistake is said first, whatever else
    secret_key()  # made now, or an empty key file refused in words before anyone signs in
    _database_ready()
    _first_start_admin()
    if not _is_loopback(args.host) and not _authentication_configured():
        print(_(
            "Refusing to listen on {host}: DriveBench can move motors, and authentication is not configured.\n"
            "Create an admin first (then everyone signs in; the admin adds engineers and viewers on the Users page):\n"
            "  drivebench users add admin --role admin\n"
            "or listen on 127.0.0.1 (the default) and reach it through an SSH tunnel.").format(host=args.host),
            file=sys.stderr)
        return 2
    if args.hsts and not args.tls_cert:
        raise InvalidValue(_("--hsts needs --tls-cert and --tls-key: HSTS is only sent over https."))
    _check_buses(args.bus or [])
    _apply_addressing(args)
    plant = Path(args.plant) if args.plant else None
    app = create_app(demo=args.demo, plant_file=plant, buses=args.bus or [], latency=args.latency, hsts=args.hsts,
                     settle_heap=True)
    scheme = "https" if args.tls_cert else "http"
    address = f"{scheme}://{args.host}:{args.port}"
    print((_("DriveBench on {address} with the simulated demo plant") if args.demo else _("DriveBench on {address}"))
          .format(address=address), flush=True)
    # Bus threads run Python per frame; after each socket write the event loop may wait a whole GIL switch interval
    # (5 ms default) to run again. 0.5 ms keeps live websocket updates on time (benchmarks/RESULTS.md, Monitor).
    sys.setswitchinterval(0.0005)
    # Forwarded headers only from the proxies named (uvicorn would believe any process on 127.0.0.1, so through an
    # SSH tunnel every client could choose the address the sign-in limit counts).
    forwarded = settings.forwarded_allow_ips
    # uvloop and httptools (uvicorn[standard]) where installed; httptools with a header deadline and a connection
    # limit (web/serving.py). No "server: uvicorn" header (it tells an attacker what runs, and is one header less
    # per answer); the access log only where the log level shows it (the audit log records every write; a poll per
    # second is not news).
    config = uvicorn.Config(proxied(app, forwarded), host=args.host, port=args.port, log_level=args.log_level,
                            ws_ping_interval=20, ssl_certfile=args.tls_cert, ssl_keyfile=args.tls_key,
                            proxy_headers=False, loop=_fastest("uvloop"), server_header=False,
                            access_log=args.log_level in ("info", "debug"), root_path=settings.root_path,
                            **serving.uvicorn_options(log_level=args.log_level, log_format=args.log_format))
    # over https, plain http to the port gets a 400 in words instead of an empty reply (web/https_port.py)
    server = HttpsPortServer(config) if args.tls_cert else uvicorn.Server(config)
    with i18n.using(i18n.DEFAULT), contextlib.suppress(KeyboardInterrupt):  # a request speaks its browser's
        server.run()  # language, never the server shell's
    return 0 if server.started else STARTUP_FAILURE


def health(args: argparse.Namespace) -> int:
    """Ask the server on this machine for /api/health: exit 0 when it answers ok (a container's health check)."""
    import json
    import ssl
    import urllib.request

    tls_on = settings.tls_cert_file is not None
    url = f"{'https' if tls_on else 'http'}://{args.host}:{args.port}/api/health"
    context = None
    if tls_on:  # its own certificate names the plant's host names, not the loopback address asked here
        context = ssl.create_default_context()
        context.check_hostname, context.verify_mode = False, ssl.CERT_NONE
    try:
        with urllib.request.urlopen(url, timeout=args.timeout, context=context) as response:
            status = json.load(response).get("status")
    except (OSError, ValueError) as exc:
        print(_("No health answer from {url}: {reason}").format(url=url, reason=exc), file=sys.stderr)
        return 1
    print(f"{url}: {status}")
    return 0 if status == "ok" else 1


def _fastest(module: str) -> str:
    """``module`` where it is installed (``uvicorn[standard]`` brings it), else uvicorn's pure-Python choice."""
    return module if importlib.util.find_spec(module) is not None else "auto"


def _apply_addressing(args: argparse.Namespace) -> None:
    """The names the server answers to, where its links point, which proxies it believes: options over settings."""
    names = [*settings.allowed_hosts, *(args.allowed_host or [])]
    if args.host not in ("0.0.0.0", "::", "") and not _is_loopback(args.host):
        names.append(args.host)  # the address it listens on is one of its names
    settings.allowed_hosts = list(dict.fromkeys(names))
    settings.public_url = args.public_url or settings.public_url
    if settings.public_url and not re.fullmatch(r"https?://[^/\s?#]+(/[^\s?#]*)?", settings.public_url):
        raise InvalidValue(_("--public-url {url} is not a web address: give it as "
                             "https://drivebench.example.com (the address others open).").format(
                                 url=repr(settings.public_url)))
    settings.forwarded_allow_ips = args.forwarded_allow_ips or settings.forwarded_allow_ips
    settings.root_path = (args.root_path if args.root_path is not None else settings.root_path).rstrip("/")
    if settings.root_path and not re.fullmatch(r"(/[A-Za-z0-9._~-]+)+", settings.root_path):
        raise InvalidValue(_("--root-path {path} is not a sub-path: give it as /drivebench (the path the reverse "
                             "proxy serves DriveBench under).").format(path=repr(settings.root_path)))


def tls(args: argparse.Namespace) -> int:
    from drivebench.web.tls import self_signed, write_pair

    certificate = self_signed(args.host, days=args.days)
    cert_file, key_file = write_pair(certificate, Path(args.out))
    print(_("Certificate {cert} (for {hosts}, {days} days) and key {key}.\n"
            "SHA-256 fingerprint (compare it with what the browser shows before trusting it):\n  {fingerprint}\n"
            "Serve with: drivebench serve --host 0.0.0.0 --tls-cert {cert} --tls-key {key}").format(
              cert=cert_file, hosts=", ".join(args.host), days=args.days, key=key_file,
              fingerprint=certificate.sha256))
    return 0


def _database_ready() -> None:
    """Wait for the database (``DRIVEBENCH_DATABASE_WAIT_S``), then bring its schema to this release's; a database
    that stays unreachable, or one a newer release has upgraded, ends the start with what to check."""
    from drivebench.errors import DatabaseUnavailable
    from drivebench.services.storage import reachability
    from drivebench.services.storage.database import upgrade_to_head

    def waiting(failure: DatabaseUnavailable) -> None:
        print(_("Waiting up to {seconds} s for the database: {reason}").format(
            seconds=f"{settings.database_wait_s:g}", reason=failure.shown_detail()), file=sys.stderr, flush=True)

    reachability.wait_for_database(report=waiting)
    upgrade_to_head()


def database(args: argparse.Namespace) -> int:
    """``db upgrade``: the schema to this release's newest; ``db check``: exit 0 when it is current, 1 when not."""
    from drivebench.services.storage import reachability
    from drivebench.services.storage.database import check_schema, head_revision, upgrade_to_head

    reachability.wait_for_database(wait_s=args.wait)
    if args.action == "upgrade":
        upgrade_to_head()
        print(_("The database schema is current (revision {revision}).").format(revision=head_revision()))
        return 0
    current, head = check_schema(), head_revision()
    if current == head:
        print(_("The database schema is current (revision {revision}).").format(revision=head))
        return 0
    print(_("The database schema is at revision {current}; this release needs {head}: run `drivebench db "
            "upgrade` (the server also upgrades it when it starts).").format(current=current or _("none"), head=head))
    return 1


def _first_start_admin() -> None:
    """The admin named by DRIVEBENCH_ADMIN_USER with the password of DRIVEBENCH_ADMIN_PASSWORD(_FILE), made on a
    database without users; later starts leave the users alone. The password is never printed."""
    given, file = settings.admin_password, settings.admin_password_file
    if given is None and file is None:
        return
    if given is not None and file is not None:
        raise InvalidValue(_("Both DRIVEBENCH_ADMIN_PASSWORD and DRIVEBENCH_ADMIN_PASSWORD_FILE are set: "
                             "keep one (the file, e.g. a container secret, is better)."))
    from drivebench.services.storage.database import upgrade_to_head
    from drivebench.services.users import accounts

    upgrade_to_head()
    if accounts.list_users():
        print(_("Users exist already: the DRIVEBENCH_ADMIN_* settings are not used (a new password: "
                "`drivebench users passwd NAME`)."), flush=True)
        return
    if file is not None:
        try:
            password = file.read_text(encoding="utf-8").rstrip("\r\n")  # a secret file's last line break
        except (OSError, UnicodeDecodeError) as exc:
            why = exc.strerror if isinstance(exc, OSError) else _("it is not UTF-8 text")
            raise InvalidValue(_("Cannot read the admin password from DRIVEBENCH_ADMIN_PASSWORD_FILE={file}: "
                                 "{reason}.").format(file=file, reason=why)) from None
    else:
        password = given.get_secret_value() if given is not None else ""
    admin = accounts.create_first_admin(settings.admin_user, password)
    if admin is not None:
        print(_("First start: created the admin {name} (password from {setting}); everyone signs in.").format(
            name=admin.name, setting="DRIVEBENCH_ADMIN_PASSWORD_FILE" if file else "DRIVEBENCH_ADMIN_PASSWORD"),
            flush=True)


def _authentication_configured() -> bool:
    from drivebench.services.storage.database import upgrade_to_head
    from drivebench.services.users import accounts

    upgrade_to_head()
    return accounts.authentication_configured()


def _read_password(args: argparse.Namespace) -> str:
    """From stdin (``--password-stdin``: the first line) or typed twice at a prompt."""
    if args.password_stdin:
        return sys.stdin.readline().rstrip("\r\n")
    import getpass

    first = getpass.getpass(_("Password: "))
    if getpass.getpass(_("Password again: ")) != first:
        raise InvalidValue(_("The two passwords differ: nothing was changed."))
    return first


def users(args: argparse.Namespace) -> int:
    from drivebench.services.storage.database import upgrade_to_head
    from drivebench.services.users import accounts

    upgrade_to_head()
    if args.action == "list":
        for user in accounts.list_users():
            status = _("disabled") if user.disabled else _("active")
            print(f"{user.name:<24} {user.role.label:<9} {status:<9} "
                  + _("created {time}").format(time=f"{user.created:%Y-%m-%d %H:%M}"))
        if not accounts.authentication_configured():
            print(_("No enabled admin: signing in is off (the server trusts its local user)."))
        return 0
    if args.action == "add":
        user = accounts.create_user(args.name, _read_password(args), _role(args.role))
        print(_("Added {name} ({role}).").format(name=user.name, role=user.role.label))
        if user.role is Role.ADMIN:
            print(_("Signing in is on: everyone who opens DriveBench signs in now."))
    elif args.action == "passwd":
        accounts.set_password(args.name, _read_password(args), end_tokens=True)
        print(_("New password set for {name}; their open sessions and API tokens end.").format(name=args.name))
    elif args.action in ("disable", "enable"):
        accounts.set_disabled(args.name, args.action == "disable")
        done = _("Disabled {name}.") if args.action == "disable" else _("Enabled {name}.")
        print(done.format(name=args.name))
    return 0


def _role(text: str) -> Role:
    try:
        return Role.parse(text)
    except ValueError as exc:
        raise InvalidValue(str(exc)) from None


def tokens(args: argparse.Namespace) -> int:
    from drivebench.services.storage.database import upgrade_to_head
    from drivebench.services.users import accounts

    upgrade_to_head()
    if args.action == "create":
        issued = accounts.issue_token(args.user, args.name, _role(args.role))
        print(_("Token '{name}' of {owner} ({role}); shown this once:").format(
            name=issued.token.name, owner=issued.token.owner, role=issued.token.role.label), file=sys.stderr)
        print(issued.secret)
    elif args.action == "list":
        for token in accounts.list_tokens(args.user):
            used = _("last used {time}").format(time=token.last_used) if token.last_used else _("never used")
            print(f"{token.id:>4} {token.name:<24} {token.owner:<16} {token.role.label:<9} {token.hint}… "
                  + (_("revoked") if token.revoked else used))
    elif args.action == "revoke":
        token = accounts.revoke_token(args.id)
        print(_("Revoked token {id} '{name}' of {owner}.").format(id=token.id, name=token.name, owner=token.owner))
    return 0


def _check_buses(specs: list[str]) -> None:
    """Open and close each --bus once before the server starts, so a wrong interface, a missing adapter or an
    unreachable gateway ends the command with its message and hint (a DriveBenchError) instead of a traceback
    from the server's start-up."""
    from drivebench.services.bus.fieldbus import open_network, parse_spec
    from drivebench.transport.bus import BusSpec, open_bus

    for text in specs:
        spec = parse_spec(text)
        if isinstance(spec, BusSpec):
            open_bus(spec).shutdown()
            continue
        network = open_network(spec, settings.sdo_timeout_s, settings.sdo_retries)
        try:  # a mailbox gateway answers with its master's address list, or the command ends saying it is silent
            network.scan()
        finally:
            network.close()


def simulate(args: argparse.Namespace) -> int:
    """Put the simulated drives of a plant file on a bus of their own (a hub, a gateway, any adapter)."""
    from drivebench.device.profiles.loader import ProfileRegistry
    from drivebench.simulator.plant import Plant, PlantFile

    plant_file = PlantFile.load(Path(args.plant) if args.plant else settings.plants_dir / "demo.json")
    registry = ProfileRegistry()
    plant = Plant(plant_file, registry.get, bus=args.bus, latency=args.latency).start() if plant_file.nodes else None
    if plant is not None:
        print(i18n.ngettext("Simulating {count} node of '{plant}' on {bus}: {nodes}",
                            "Simulating {count} nodes of '{plant}' on {bus}: {nodes}", len(plant.nodes)).format(
            count=len(plant.nodes), plant=plant_file.name, bus=plant.spec,
            nodes=", ".join(f"{n.node_id} {n.name}" for n in plant.nodes.values())), flush=True)
    gateway = None
    if plant_file.ethercat is not None:
        gateway = plant_file.ethercat.start(registry.get, port=args.ethercat_port, latency=args.latency)
        slaves = ", ".join(_("station {station} {name}").format(station=s.station, name=s.name)
                           for s in gateway.slaves.values())
        print(i18n.ngettext("Simulating {count} EtherCAT slave of '{plant}' behind {gateway}: {slaves}",
                            "Simulating {count} EtherCAT slaves of '{plant}' behind {gateway}: {slaves}",
                            len(gateway.slaves)).format(count=len(gateway.slaves), plant=plant_file.ethercat.name,
                                                        gateway=gateway.spec, slaves=slaves), flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    finally:
        if gateway is not None:
            gateway.stop()
        if plant is not None:
            plant.stop()
    return 0


def hub(args: argparse.Namespace) -> int:
    from drivebench.transport.hub import serve_hub
    from drivebench.transport.hub_bridge import BusBridge

    if not _is_loopback(args.host) and not args.allow_remote:
        print(_("Refusing to listen on {host}: anyone who reaches the hub can send frames to the drives.\n"
                "Keep the default 127.0.0.1, or, on a closed machine network, start with --allow-remote.").format(
                    host=args.host), file=sys.stderr)
        return 2
    bridges = [BusBridge(spec, args.channel) for spec in args.bridge or []]

    def listening(host: str, port: int) -> None:
        print(_("socketcand hub on {host}:{port} (python-can: interface='socketcand', host='{host}', port={port}, "
                "channel='{channel}'; bus spec socketcand:{host}:{port}/{channel})").format(
                    host=host, port=port, channel=args.channel)
              + "".join("\n  " + _("{channel} bridged to {bus}").format(channel=args.channel, bus=bridge.spec)
                        for bridge in bridges), flush=True)

    async def run() -> None:
        task = asyncio.current_task()
        if task is not None and threading.current_thread() is threading.main_thread():
            # SIGTERM (docker stop, a supervisor) closes the hub like Ctrl+C
            asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, task.cancel)
        with contextlib.suppress(asyncio.CancelledError):
            await serve_hub(args.host, args.port, bridges=bridges, on_listening=listening)

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run())
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="drivebench", description=_(
        "Commissioning of CANopen drives: parameters, PDOs, NMT, diagnostics."))
    sub = parser.add_subparsers(dest="command", required=True)

    p_serve = sub.add_parser("serve", help=_("run the web server"))
    p_serve.add_argument("--host", default=settings.host,
                         help=_("listen address (default 127.0.0.1; any other needs an admin user: `users add`)"))
    p_serve.add_argument("--port", type=int, default=settings.port)
    p_serve.add_argument("--bus", action="append", metavar="SPEC",
                         help=_("open a session at start-up: socketcan:can0@500000, socketcand:HOST:PORT/can0 ..."))
    p_serve.add_argument("--demo", action="store_true", help=_("start the built-in simulated plant"))
    p_serve.add_argument("--plant", help=_("start a simulated plant from this plant file"))
    p_serve.add_argument("--latency", help=_("SDO processing time of simulated drives, e.g. 30ms±20ms"))
    p_serve.add_argument("--log-level", choices=logs.LEVELS, default=settings.log_level,
                         help=_("server log level (default from DRIVEBENCH_LOG_LEVEL, else info)"))
    p_serve.add_argument("--log-format", choices=logs.FORMATS, default=settings.log_format,
                         help=_("text lines or JSON lines (default from DRIVEBENCH_LOG_FORMAT, else text)"))
    p_serve.add_argument("--tls-cert", type=Path, default=settings.tls_cert_file, metavar="FILE",
                         help=_("serve https with this PEM certificate (with --tls-key)"))
    p_serve.add_argument("--tls-key", type=Path, default=settings.tls_key_file, metavar="FILE",
                         help=_("the certificate's PEM private key"))
    p_serve.add_argument("--hsts", action="store_true", default=settings.hsts,
                         help=_("send Strict-Transport-Security (browsers then insist on https for a year)"))
    p_serve.add_argument("--allowed-host", action="append", metavar="NAME",
                         help=_("a name browsers reach the server by (repeatable; 127.0.0.1, localhost, [::1] and "
                              "--host always); any other Host or Origin is refused (DNS rebinding)"))
    p_serve.add_argument("--public-url", metavar="URL",
                         help=_("the address others open, e.g. https://drivebench.example.com (share links point "
                              "there; default: the address the server was reached at)"))
    p_serve.add_argument("--forwarded-allow-ips", metavar="IPS",
                         help=_("reverse proxies whose X-Forwarded-For/-Proto are believed, comma-separated "
                              "(default: none)"))
    p_serve.add_argument("--root-path", metavar="PATH",
                         help=_("the sub-path a reverse proxy serves DriveBench under, e.g. /drivebench (the proxy "
                              "strips it; default from DRIVEBENCH_ROOT_PATH, else none)"))
    p_serve.set_defaults(func=serve)

    p_health = sub.add_parser("health", help=_("exit 0 if the server on this machine answers /api/health"))
    p_health.add_argument("--host", default="127.0.0.1")
    p_health.add_argument("--port", type=int, default=settings.port)
    p_health.add_argument("--timeout", type=float, default=4.0, help=_("seconds"))
    p_health.set_defaults(func=health)

    p_tls = sub.add_parser("tls", help=_("certificates for https"))
    tls_sub = p_tls.add_subparsers(dest="action", required=True)
    p_self = tls_sub.add_parser("self-signed", help=_("make a self-signed certificate and key for a plant network"))
    p_self.add_argument("--host", action="append", required=True, metavar="NAME",
                        help=_("a name or address the browsers use (repeat for each)"))
    p_self.add_argument("--out", default="var/tls", help=_("folder for drivebench.crt and drivebench.key"))
    p_self.add_argument("--days", type=int, default=825)
    p_tls.set_defaults(func=tls)

    p_sim = sub.add_parser("simulate", help=_("run simulated drives on a bus"))
    p_sim.add_argument("--bus", help=_("bus for the drives (default: the plant file's), e.g. "
                                     "socketcand:127.0.0.1:29536/can0"))
    p_sim.add_argument("--plant", help=_("plant file (default: the demo plant)"))
    p_sim.add_argument("--ethercat-port", type=int,
                       help=_("UDP port of the simulated EtherCAT master's mailbox gateway on 127.0.0.1 (default: the "
                              "plant file's, 0 = any free one)"))
    p_sim.add_argument("--latency", help=_("SDO processing time, e.g. 30ms±20ms"))
    p_sim.set_defaults(func=simulate)

    p_hub = sub.add_parser("hub", help=_("run a socketcand-protocol hub so processes share one bus"))
    p_hub.add_argument("--host", default="127.0.0.1")
    p_hub.add_argument("--port", type=int, default=29536, help=_("TCP port (0 picks a free one and prints it)"))
    p_hub.add_argument("--channel", default="can0", help=_("channel the --bridge buses join (default can0)"))
    p_hub.add_argument("--bridge", action="append", metavar="SPEC",
                       help=_("also relay frames to and from this python-can bus, e.g. socketcan:can0@500000"))
    p_hub.add_argument("--allow-remote", action="store_true",
                       help=_("allow listening on a non-loopback address (no authentication)"))
    p_hub.set_defaults(func=hub)

    p_users = sub.add_parser("users", help=_("users who sign in (the first admin switches signing in on)"))
    users_sub = p_users.add_subparsers(dest="action", required=True)
    p_add = users_sub.add_parser("add", help=_("add a user"))
    p_add.add_argument("name")
    p_add.add_argument("--role", required=True, choices=["admin", "engineer", "viewer"])
    p_add.add_argument("--password-stdin", action="store_true", help=_("read the password from stdin's first line"))
    users_sub.add_parser("list", help=_("list the users"))
    for action, text in [("disable", _("disable a user (cannot sign in, tokens stop working)")),
                         ("enable", _("enable a disabled user"))]:
        users_sub.add_parser(action, help=text).add_argument("name")
    p_passwd = users_sub.add_parser("passwd", help=_("set a new password"))
    p_passwd.add_argument("name")
    p_passwd.add_argument("--password-stdin", action="store_true", help=_("read the password from stdin's first line"))
    p_users.set_defaults(func=users)

    p_tokens = sub.add_parser("tokens", help=_("API tokens for scripts (Authorization: Bearer dbt_...)"))
    tokens_sub = p_tokens.add_subparsers(dest="action", required=True)
    p_create = tokens_sub.add_parser("create", help=_("create a token and print it (once)"))
    p_create.add_argument("name", help=_("what the token is for"))
    p_create.add_argument("--user", required=True, help=_("the user the token acts for"))
    p_create.add_argument("--role", required=True, choices=["admin", "engineer", "viewer"],
                          help=_("no higher than the user's role"))
    p_list = tokens_sub.add_parser("list", help=_("list tokens (never the tokens themselves)"))
    p_list.add_argument("--user")
    tokens_sub.add_parser("revoke", help=_("revoke a token")).add_argument("id", type=int)
    p_tokens.set_defaults(func=tokens)

    p_db = sub.add_parser("db", help=_("the database schema (DRIVEBENCH_DATABASE_URL)"))
    db_sub = p_db.add_subparsers(dest="action", required=True)
    db_sub.add_parser("upgrade", help=_("bring the schema to this release's (servers also do it when they start)"))
    db_sub.add_parser("check", help=_("exit 0 if the schema is this release's, 1 if it needs an upgrade or is newer"))
    p_db.add_argument("--wait", type=float, default=0.0, metavar="SECONDS",
                      help=_("wait this long for an unreachable database (default: fail at once)"))
    p_db.set_defaults(func=database)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Messages in the language of the shell (LC_ALL, LC_MESSAGES, LANG: ``LANG=de_DE.UTF-8`` gives German)."""
    with i18n.using(i18n.from_environment(os.environ)):
        args = build_parser().parse_args(argv)
        try:
            return int(args.func(args))
        except SQLAlchemyError as exc:  # the database failed after it answered once: in words, no traceback
            from drivebench.services.storage.reachability import unavailable

            problem = unavailable(exc)
            print(f"drivebench: {problem.shown_detail()}\n  {problem.shown_hint()}", file=sys.stderr)
            return 1
        except DriveBenchError as exc:
            hint = f"\n  {_(exc.hint)}" if exc.hint else ""
            print(f"drivebench: {exc.shown_detail()}{hint}", file=sys.stderr)
            return 1


if __name__ == "__main__":
    sys.exit(main())
