"""``drivebench serve | simulate | hub``."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import ipaddress
import signal
import sys
import threading
from pathlib import Path

from drivebench.config import settings
from drivebench.errors import DriveBenchError


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def serve(args: argparse.Namespace) -> int:
    import uvicorn

    from drivebench.web.app import create_app

    if not _is_loopback(args.host) and not args.allow_remote:
        print(
            f"Refusing to listen on {args.host}: DriveBench can move motors, and authentication is not configured.\n"
            "Listen on 127.0.0.1 (the default) and reach it through an SSH tunnel, or, on a closed machine network\n"
            "where everyone may operate the drives, start with --allow-remote.", file=sys.stderr)
        return 2
    _check_buses(args.bus or [])
    plant = Path(args.plant) if args.plant else None
    app = create_app(demo=args.demo, plant_file=plant, buses=args.bus or [], latency=args.latency)
    print(f"DriveBench on http://{args.host}:{args.port}"
          + (" with the simulated demo plant" if args.demo else ""), flush=True)
    # Bus threads run Python per frame; after each socket write the event loop may wait a whole GIL switch interval
    # (5 ms default) to run again. 0.5 ms keeps live websocket updates on time (benchmarks/RESULTS.md, Monitor).
    sys.setswitchinterval(0.0005)
    uvicorn.run(app, host=args.host, port=args.port, log_level=args.log_level, ws_ping_interval=20)
    return 0


def _check_buses(specs: list[str]) -> None:
    """Open and close each --bus once before the server starts, so a wrong interface, a missing adapter or an
    unreachable gateway ends the command with its message and hint (a DriveBenchError) instead of a traceback
    from the server's start-up."""
    from drivebench.transport.bus import BusSpec, open_bus

    for text in specs:
        open_bus(BusSpec.parse(text)).shutdown()


def simulate(args: argparse.Namespace) -> int:
    """Put the simulated drives of a plant file on a bus of their own (a hub, a gateway, any adapter)."""
    from drivebench.device.loader import ProfileRegistry
    from drivebench.simulator.plant import Plant, PlantFile

    plant_file = PlantFile.load(Path(args.plant) if args.plant else settings.plants_dir / "demo.json")
    registry = ProfileRegistry()
    plant = Plant(plant_file, registry.get, bus=args.bus, latency=args.latency).start()
    print(f"Simulating {len(plant.nodes)} node(s) of '{plant_file.name}' on {plant.spec}: "
          + ", ".join(f"{n.node_id} {n.name}" for n in plant.nodes.values()), flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    finally:
        plant.stop()
    return 0


def hub(args: argparse.Namespace) -> int:
    from drivebench.transport.hub import serve_hub
    from drivebench.transport.hub_bridge import BusBridge

    if not _is_loopback(args.host) and not args.allow_remote:
        print(f"Refusing to listen on {args.host}: anyone who reaches the hub can send frames to the drives.\n"
              "Keep the default 127.0.0.1, or, on a closed machine network, start with --allow-remote.",
              file=sys.stderr)
        return 2
    bridges = [BusBridge(spec, args.channel) for spec in args.bridge or []]

    def listening(host: str, port: int) -> None:
        print(f"socketcand hub on {host}:{port} (python-can: interface='socketcand', host='{host}', port={port}, "
              f"channel='{args.channel}'; bus spec socketcand:{host}:{port}/{args.channel})"
              + "".join(f"\n  {args.channel} bridged to {bridge.spec}" for bridge in bridges), flush=True)

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
    parser = argparse.ArgumentParser(prog="drivebench", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p_serve = sub.add_parser("serve", help="run the web server")
    p_serve.add_argument("--host", default=settings.host)
    p_serve.add_argument("--port", type=int, default=settings.port)
    p_serve.add_argument("--bus", action="append", metavar="SPEC",
                         help="open a session at start-up: socketcan:can0@500000, socketcand:HOST:PORT/can0 ...")
    p_serve.add_argument("--demo", action="store_true", help="start the built-in simulated plant")
    p_serve.add_argument("--plant", help="start a simulated plant from this plant file")
    p_serve.add_argument("--latency", help="SDO processing time of simulated drives, e.g. 30ms±20ms")
    p_serve.add_argument("--allow-remote", action="store_true",
                         help="allow listening on a non-loopback address without authentication")
    p_serve.add_argument("--log-level", default="warning")
    p_serve.set_defaults(func=serve)

    p_sim = sub.add_parser("simulate", help="run simulated drives on a bus")
    p_sim.add_argument("--bus", help="bus for the drives (default: the plant file's), e.g. "
                                     "socketcand:127.0.0.1:29536/can0")
    p_sim.add_argument("--plant", help="plant file (default: the demo plant)")
    p_sim.add_argument("--latency", help="SDO processing time, e.g. 30ms±20ms")
    p_sim.set_defaults(func=simulate)

    p_hub = sub.add_parser("hub", help="run a socketcand-protocol hub so processes share one bus")
    p_hub.add_argument("--host", default="127.0.0.1")
    p_hub.add_argument("--port", type=int, default=29536, help="TCP port (0 picks a free one and prints it)")
    p_hub.add_argument("--channel", default="can0", help="channel the --bridge buses join (default can0)")
    p_hub.add_argument("--bridge", action="append", metavar="SPEC",
                       help="also relay frames to and from this python-can bus, e.g. socketcan:can0@500000")
    p_hub.add_argument("--allow-remote", action="store_true",
                       help="allow listening on a non-loopback address (no authentication)")
    p_hub.set_defaults(func=hub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except DriveBenchError as exc:
        print(f"drivebench: {exc.detail}" + (f"\n  {exc.hint}" if exc.hint else ""), file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
