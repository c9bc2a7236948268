"""Scope display latency and the sample stream against the bus (issue 31): the app served by uvicorn with the demo
plant, a recording of the CiA 402 servo (node 7: 0x6064, 0x606C; sampled by PDO at ``--period-ms``, default 1 ms)
started over the HTTP API, watched by three real websocket clients (``websockets``, standing in for three browsers,
in a process of their own: three Chromiums beside the server are too heavy for this shared 2-core machine; a browser
adds its drawing, not the transport measured here).

Reported per run: the end-to-end latency from the moment a second python-can bus on the plant's virtual channel sees
sample n's SYNC to the moment a client receives the row of sample n, and the same path in parts, per sample:

1. SYNC on the wire -> the last TPDO frame answering it reaches the source's bus thread (the simulated drive's answer
   and the virtual bus);
2. -> the sample delivered to the run (the hop from the bus thread to the event loop and the wait for every node);
3. -> the row handed to a viewer's socket (the socket's batching, the loop's other work, the JSON encoding);
4. -> the row received by the viewer (the send, the loopback, the viewer's own loop).

The timestamps come from wrappers this script puts around the source's bus-thread entry and SYNC assignment
(``PdoScopeSource.on_bus_frame``, ``_answered``), the run's ``on_frame`` and Starlette's ``WebSocket.send``: the
product carries no timing code. CPU: the server process's (uvicorn, the simulated plant, the SYNC producer, this
script's wire listener and wrappers) and the viewers' process, over the watched time, with the threads that took
most of it. Also the frames against the samples: every value a viewer received against the TPDO frame that
carried it.

Each run is a child process at its own priority (``--nice``, e.g. -5 and 0; we are root), optionally alternating
with the code before a change (``--before <backend dir>``): before/after interleaved in one period of load.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import math
import os
import resource
import struct
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve()
HEADING = "## Scope: display latency with three viewers, samples against the bus"
AXIS = 7
CLIENTS = 3
API = "/api/sessions/demo-plant"
PARTS = [("wire", "SYNC→TPDO", "SYNC on the wire -> the last TPDO answering it in the source's bus thread"),
         ("run", "TPDO→run", "TPDO received -> the sample delivered to the run"),
         ("socket", "run→socket", "delivered -> the row handed to the viewer's socket"),
         ("send", "send", "handed to the socket -> the send returned (its frame written to the transport)"),
         ("client", "sent→viewer", "the send returned -> received by the viewer (the kernel, the viewers' process)"),
         ("total", "end to end", "SYNC on the wire -> received by the viewer")]


def percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(share * (len(ordered) - 1)))] if ordered else float("nan")


# --- the viewers' process -------------------------------------------------------------------------------------------
async def _watch(url: str, until: float, seen: list[tuple[int, float]]) -> None:
    import websockets

    async with websockets.connect(url, max_size=None) as socket:
        while time.monotonic() < until:
            try:
                text = await asyncio.wait_for(socket.recv(), timeout=max(0.1, until - time.monotonic()))
            except TimeoutError:
                break
            arrived = time.monotonic()
            message = json.loads(text)
            if message["type"] == "rows":
                seen.extend((row[0], arrived, *row[2:]) for row in message["rows"])


def viewers(url: str, until: float) -> None:
    """Run :data:`CLIENTS` viewers until ``until`` (monotonic, system-wide on Linux); print what each received."""
    seen: list[list[Any]] = [[] for _ in range(CLIENTS)]
    late: list[float] = []

    async def ticker() -> None:
        """How late the viewers' loop wakes for a 5 ms sleep (its process waiting for a core, or busy)."""
        while time.monotonic() < until:
            asked = time.monotonic() + 0.005
            await asyncio.sleep(0.005)
            late.append(time.monotonic() - asked)

    async def everyone() -> None:
        await asyncio.gather(ticker(), *(_watch(f"{url}?viewer={i}", until, found) for i, found in enumerate(seen)))

    asyncio.run(everyone())
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"seen": seen, "cpu_s": usage.ru_utime + usage.ru_stime, "late_ms": spread(late)}))


# --- the server's process -------------------------------------------------------------------------------------------
class Probe:
    """Timestamps of each sample's way through the server, taken by wrappers around the product's functions."""

    def __init__(self) -> None:
        self.received: dict[int, list[float]] = defaultdict(list)
        """Per TPDO COB-ID, when each of its frames reached the source's bus thread, in order."""
        self.answered: dict[int, list[int]] = defaultdict(list)
        """Per TPDO COB-ID, the sample each of its frames was put to, in the same order."""
        self.delivered: dict[int, float] = {}
        self.sent: list[tuple[str, float, float, str]] = []
        """(viewer, handed, written, text) of each message handed to a viewer's socket: when the send was called and
        when it returned (its frame written to the connection's transport)."""
        self.collections: list[tuple[int, float]] = []
        """(generation, seconds) of each of the garbage collector's runs in the server process."""
        self._collecting: float | None = None

    def on_gc(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._collecting = time.perf_counter()
        elif self._collecting is not None:
            self.collections.append((info["generation"], time.perf_counter() - self._collecting))
            self._collecting = None

    def pauses(self) -> dict[str, list[float]]:
        """Per generation: count, p99 and longest collection [ms]."""
        found: dict[str, list[float]] = {}
        for generation in (0, 1, 2):
            spent = [seconds for gen, seconds in self.collections if gen == generation]
            found[str(generation)] = [len(spent), 1000 * percentile(spent, 0.99), 1000 * max(spent, default=0.0)]
        return found

    def install(self) -> None:
        from starlette.websockets import WebSocket

        from drivebench.services.scope import pdo_source, runs

        probe = self
        source_class, run_class = pdo_source.PdoScopeSource, runs.ScopeRun
        on_bus_frame, answered, on_frame = source_class.on_bus_frame, source_class._answered, run_class.on_frame
        send = WebSocket.send

        def timed_bus_frame(self: Any, cob_id: int, data: bytes) -> None:
            if cob_id in self._cobs:
                probe.received[cob_id].append(time.monotonic())
            on_bus_frame(self, cob_id, data)

        def timed_answered(self: Any, cob_id: int, stamp: int) -> int:
            sample: int = answered(self, cob_id, stamp)
            probe.answered[cob_id].append(sample)
            return sample

        def timed_frame(self: Any, frame: Any) -> None:
            probe.delivered.setdefault(frame.sample, time.monotonic())
            on_frame(self, frame)

        async def timed_send(self: Any, message: Any) -> None:
            text = message.get("text") or (message.get("bytes") or b"").decode()
            if message.get("type") != "websocket.send" or not text.startswith('{"type":"rows"'):
                await send(self, message)
                return
            handed = time.monotonic()
            await send(self, message)
            probe.sent.append((self.query_params.get("viewer", "?"), handed, time.monotonic(), text))

        source_class.on_bus_frame = timed_bus_frame  # type: ignore[method-assign]
        source_class._answered = timed_answered  # type: ignore[method-assign]
        run_class.on_frame = timed_frame  # type: ignore[method-assign]
        WebSocket.send = timed_send  # type: ignore[method-assign]

    def last_received(self) -> dict[int, float]:
        """When the last TPDO frame answering each sample reached the source's bus thread."""
        found: dict[int, float] = {}
        for cob, times in self.received.items():
            for at, sample in zip(times, self.answered[cob], strict=False):
                found[sample] = max(found.get(sample, 0.0), at)
        return found

    def handed(self) -> dict[str, dict[int, tuple[float, float]]]:
        """Per viewer, when each sample's row was handed to its socket and when that send returned."""
        found: dict[str, dict[int, tuple[float, float]]] = defaultdict(dict)
        for viewer, at, written, text in self.sent:
            for row in json.loads(text)["rows"]:
                found[viewer].setdefault(row[0], (at, written))
        return found


def thread_cpu() -> dict[str, float]:
    """CPU seconds of each live thread of this process, by Python thread name (others by their OS id)."""
    names = {thread.native_id: thread.name for thread in threading.enumerate()}
    tick = os.sysconf("SC_CLK_TCK")
    found: dict[str, float] = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        name = names.get(int(task.name), f"thread {task.name}").replace("Notifier for bus", "notifier")
        found[name] = found.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return found


def name_threads(app: Any, session: Any) -> None:
    """The bus threads by what they serve (python-can names both after the same channel)."""
    from drivebench.protocol.canopen.network import frames_of

    for owner, notifier in (("plant", app.state.drivebench.plants["demo-plant"]._notifier),
                            ("session", frames_of(session.network).canopen.notifier)):
        for reader in getattr(notifier, "_readers", []):
            if isinstance(reader, threading.Thread):
                reader.name = f"{owner} bus thread"


def process_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def answered_frames(seen: list[tuple[int, int, bytes]], cobs: set[int], lag: int) -> dict[int, dict[int, bytes]]:
    """Each frame of the recording's TPDOs by the SYNC it answers, as CiA 301 has a "synchronous every SYNC" TPDO
    answer: each SYNC once, in order (the frame after the one for SYNC n answers n + 1 even when it comes after a
    later SYNC), never a SYNC not sent yet; a node more than ``lag`` SYNCs behind skipped SYNCs. A second frame for
    one SYNC means the frames before it were put one SYNC too late (the node was behind when its first frame came):
    they move one back where there is room (within ``lag``), as the source moves them (``_shift_back``)."""
    found: dict[int, dict[int, bytes]] = {}
    expected: dict[int, int] = {}
    for stamp, cob, data in seen:
        if cob not in cobs:
            continue
        sample = stamp if cob not in expected or stamp - expected[cob] > lag else min(expected[cob], stamp)
        expected[cob] = sample + 1
        if cob in found.get(sample, {}):
            first = sample
            while first - 1 >= max(0, sample - lag) and cob in found.get(first - 1, {}):
                first -= 1
            if first - 1 < max(0, sample - lag):
                continue  # no room: a frame too many, as the source counts it
            for number in range(first, sample + 1):
                found.setdefault(number - 1, {})[cob] = found[number].pop(cob)
        found.setdefault(sample, {})[cob] = data
    return found


def spread(values: list[float]) -> dict[str, float]:
    return {"p50": 1000 * percentile(values, 0.5), "p99": 1000 * percentile(values, 0.99),
            "max": 1000 * max(values, default=float("nan")), "count": len(values)}


def serve_and_watch(seconds: float, period_ms: float) -> dict[str, Any]:
    import can
    import httpx
    import uvicorn

    from drivebench.cli import _fastest
    from drivebench.config import REPO_ROOT
    from drivebench.services.scope import pdo_source, runs
    from drivebench.web import serving
    from drivebench.web.app import create_app
    from drivebench.web.ws import scope as scope_socket

    class Wire(can.Listener):
        """SYNC arrival times by SYNC number and node 7's TPDO frames as they came."""

        def __init__(self) -> None:
            self.lock = threading.Lock()
            self.syncs: list[float] = []
            self.frames: list[tuple[int, int, bytes]] = []
            self.counting = False

        def on_message_received(self, msg: can.Message) -> None:
            now = time.monotonic()
            with self.lock:
                if not self.counting:
                    return
                if msg.arbitration_id == 0x080:
                    self.syncs.append(now)
                elif 0x180 <= msg.arbitration_id < 0x580 and msg.arbitration_id & 0x7F == AXIS and self.syncs:
                    self.frames.append((len(self.syncs) - 1, msg.arbitration_id, bytes(msg.data)))

    probe = Probe()
    probe.install()
    channel = f"scope-latency-{os.getpid()}"
    # served as `drivebench serve` serves (cli.serve): the heap settled after start-up, a 0.5 ms GIL switch interval,
    # uvloop, its HTTP protocol and websocket ping
    app = create_app(plant_file=REPO_ROOT / "plants" / "demo.json", plant_bus=f"virtual:{channel}@500000",
                     latency="0ms", settle_heap=True)
    sys.setswitchinterval(0.0005)
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, ws_ping_interval=20, loop=_fastest("uvloop"),
                                           server_header=False, timeout_graceful_shutdown=5,
                                           **serving.uvicorn_options(log_level="warning")))
    import socket as sockets

    sock = sockets.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True, name="uvicorn")
    thread.start()
    wire_bus = can.Bus(interface="virtual", channel=channel)
    wire = Wire()
    notifier = can.Notifier(wire_bus, [wire])
    load_before = os.getloadavg()[0]
    try:
        while not server.started:
            time.sleep(0.05)
        base = f"http://127.0.0.1:{port}"
        body = {"channels": [{"node": AXIS, "ref": "0x6064"}, {"node": AXIS, "ref": "0x606C"}],
                "period_ms": period_ms, "length_s": seconds * 10, "trigger": {"mode": "free"}, "name": "latency"}
        with httpx.Client(base_url=base, timeout=30) as http:
            asked = http.post(f"{API}/scope/run", json=body)
            if asked.status_code == 428:
                problem = asked.json()
                with wire.lock:
                    wire.counting = True  # SYNC 0 is the first one after this start
                asked = http.post(f"{API}/scope/run", json={**body, "confirm": problem["confirm_node"],
                                                            "confirm_values": problem["confirm_values"]})
            assert asked.status_code == 201 and asked.json()["source"] == "pdo", asked.text
            session = app.state.drivebench.manager.get("demo-plant")
            recording = runs.current(session)
            infos = recording.infos
            part = getattr(recording.source, "pdo", recording.source)  # the joined source's PDO part
            cobs = {tpdo.cob_id for tpdo in part.plan.tpdos}
            name_threads(app, session)
            until = time.monotonic() + seconds
            cpu_before, threads_before = process_cpu(), thread_cpu()
            gc.callbacks.append(probe.on_gc)
            watched = subprocess.run([sys.executable, str(HERE), "--viewers",
                                      f"ws://127.0.0.1:{port}/ws/sessions/demo-plant/scope", str(until)],
                                     capture_output=True, text=True, check=True)
            cpu_s, threads_after = process_cpu() - cpu_before, thread_cpu()
            gc.callbacks.remove(probe.on_gc)
            stopped = http.post(f"{API}/scope/run/stop").json()
    finally:
        notifier.stop()
        wire_bus.shutdown()
        server.should_exit = True
        thread.join(timeout=15)
        sock.close()
    viewed = json.loads(watched.stdout)
    seen: list[list[list[Any]]] = viewed["seen"]
    with wire.lock:
        syncs, seen_frames = list(wire.syncs), list(wire.frames)
    frames = answered_frames(seen_frames, cobs, max(3, math.ceil(pdo_source.WAIT_S * 1000 / period_ms)))
    start_s = min(row[1] for found in seen for row in found) + 1.0  # past the backlog a late viewer gets
    received, handed = probe.last_received(), probe.handed()
    parts: dict[str, list[float]] = {name: [] for name, _, _ in PARTS}
    for viewer, found in enumerate(seen):
        to_socket = handed.get(str(viewer), {})
        for sample, arrived, *_ in found:
            if sample >= len(syncs) or arrived < start_s or sample not in received or sample not in to_socket:
                continue
            sync, got, delivered = syncs[sample], received[sample], probe.delivered[sample]
            sent, written = to_socket[sample]
            for name, value in (("wire", got - sync), ("run", delivered - got), ("socket", sent - delivered),
                                ("send", written - sent), ("client", arrived - written), ("total", arrived - sync)):
                parts[name].append(value)
    carried, equal = 0, 0
    unequal: list[list[Any]] = []
    for sample, _, *values in seen[0]:
        for position, value in enumerate(values):
            if value is None:
                continue
            carried += 1
            matches = [struct.unpack_from("<i", data, 4 * position)[0] for data in frames.get(sample, {}).values()
                       if len(data) >= 4 * position + 4]
            same = any(infos[position].value(raw) == value for raw in matches)
            equal += same
            if not same and len(unequal) < 5:
                unequal.append([sample, position, value, [infos[position].value(raw) for raw in matches],
                                len(syncs)])
    busiest = sorted(((threads_after.get(name, 0.0) - threads_before.get(name, 0.0),
                       name.replace(f'"Virtual bus channel {channel}"', "(the script's wire)").replace(channel, "…"))
                      for name in threads_after), reverse=True)[:4]
    mean_ms = 1000 * (syncs[-1] - syncs[0]) / (len(syncs) - 1) if len(syncs) > 1 else float("nan")
    return {"seconds": seconds, "period_ms": period_ms, "syncs": len(syncs), "mean_period_ms": mean_ms,
            "tpdo_frames": sum(cob in cobs for _, cob, _ in seen_frames),
            "rows": [len(found) for found in seen], "carried": carried, "equal": equal, "unequal": unequal,
            "parts_ms": {name: spread(values) for name, values in parts.items()},
            "gc_ms": probe.pauses(), "gc_tracked": len(gc.get_objects()), "server_cpu_s": cpu_s,
            "viewers_cpu_s": viewed["cpu_s"], "viewers_late_ms": viewed["late_ms"],
            "threads": [[name, round(cpu, 2)] for cpu, name in busiest],
            "min_interval_ms": 1000 * getattr(scope_socket, "MIN_INTERVAL_S", float("nan")),
            "restored": stopped.get("restored", []), "load": [load_before, os.getloadavg()[0]]}


def one(seconds: float, period_ms: float) -> None:
    from drivebench.web import heap

    heap.hold()  # as `drivebench serve`: no cyclic collection until the app has started and settled its heap
    from drivebench.config import settings
    from drivebench.services.storage import database

    db_file = Path(f"/tmp/scope-latency-{os.getpid()}.db")
    settings.database_url = f"sqlite:///{db_file}"
    try:
        result = serve_and_watch(seconds, period_ms)
    finally:
        database.dispose(settings.database_url)
        db_file.unlink(missing_ok=True)
    print(json.dumps(result))


# --- the runs and RESULTS.md ----------------------------------------------------------------------------------------
def spawn(code: str, backend: Path, nice: int, seconds: float, period_ms: float) -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": str(backend)}
    done = subprocess.run([sys.executable, str(HERE), "--one", "--seconds", str(seconds), "--period-ms",
                           str(period_ms)], env=env, capture_output=True, text=True, check=False,
                          preexec_fn=lambda: os.nice(nice) and None)
    if done.returncode != 0:
        raise SystemExit(f"run failed ({code}, nice {nice}):\n{done.stderr[-3000:]}")
    return {"code": code, "nice": nice, **json.loads(done.stdout.strip().splitlines()[-1])}


def table(results: list[dict[str, Any]]) -> str:
    lines = ["| Run | Load (start-end) | SYNCs (mean period) | " + " | ".join(
        f"{label} p50 / p99 [ms]" for _, label, _ in PARTS) + " | max [ms] | CPU server / viewers [s] | "
        "busiest server threads [CPU s] | GC passes gen 1 / gen 2 (longest [ms]) | viewers' loop late p99 / max [ms] |",
        "|---" * (len(PARTS) + 8) + "|"]
    for found in results:
        parts = found["parts_ms"]
        lines.append(
            f"| {found['code']}, nice {found['nice']} | {found['load'][0]:.1f}-{found['load'][1]:.1f} | "
            f"{found['syncs']} ({found['mean_period_ms']:.2f} ms) | "
            + " | ".join(f"{parts[name]['p50']:.1f} / {parts[name]['p99']:.1f}" for name, _, _ in PARTS)
            + f" | {parts['total']['max']:.0f} | {found['server_cpu_s']:.1f} / {found['viewers_cpu_s']:.1f} | "
            + ", ".join(f"{name} {cpu}" for name, cpu in found["threads"])
            + " | " + " / ".join(f"{count} ({longest:.0f})" for count, _, longest in
                                 (found["gc_ms"][gen] for gen in ("1", "2")))
            + f" | {found['viewers_late_ms']['p99']:.1f} / {found['viewers_late_ms']['max']:.0f} |")
    return "\n".join(lines)


def write_results(results: list[dict[str, Any]], note: str) -> None:
    sys.path.insert(0, str(HERE.parent))
    from _monitor_results import machine, write_section

    first = results[0]
    checks = "; ".join(f"{found['code']}, nice {found['nice']}: SYNCs {found['syncs']}, TPDO frames "
                       f"{found['tpdo_frames']}, values {found['carried']}, equal {found['equal']}"
                       for found in results)
    legend = "\n".join(f"* {label}: {what}" for _, label, what in PARTS)
    body = f"""Written by `benchmarks/scope_latency.py`: the app served by uvicorn with the demo plant, node 7
(0x6064, 0x606C) sampled by PDO at a {first["period_ms"]:g} ms SYNC for {first["seconds"]:g} s per run, watched by
{CLIENTS} real websocket clients in a process of their own (the `websockets` library standing in for three browsers).
Machine: {machine()}, shared with other work; {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}. Each run is a
process of its own at the priority named (`nice`; the viewers' process inherits it); runs of the code before and after
a change alternate, so they share one period of load.

Each sample's way in parts (p50 / p99 over every row the three viewers received, the first second after connecting
left out: a viewer who connects gets the last samples as a backlog first). The timestamps come from wrappers the
script puts around the source's bus-thread entry, the run's `on_frame` and Starlette's `WebSocket.send`; the product
carries no timing code. CPU: the server process (with the simulated plant, the SYNC producer and the script's wire
listener and wrappers) and the viewers' process, over the watched {first["seconds"]:g} s.

{legend}

{table(results)}

Target: end-to-end p99 < 100 ms.

Samples against the bus (each value client 1 received against the TPDO frame the in-order rule of a "synchronous
every SYNC" TPDO puts to its SYNC): {checks}.

{note}
"""
    write_section(HEADING, body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--period-ms", type=float, default=1.0)
    parser.add_argument("--nice", type=int, nargs="+", default=[-5, 0])
    parser.add_argument("--before", type=Path, help="backend/ of the code before a change: its runs alternate")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--note", default="", help="a paragraph written below the figures")
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument("--save", type=Path, help="keep the runs' figures in this JSON file")
    parser.add_argument("--load", type=Path, help="write RESULTS.md from runs kept by --save (no new runs)")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--viewers", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.viewers:
        viewers(args.viewers[0], float(args.viewers[1]))
        return
    if args.one:
        one(args.seconds, args.period_ms)
        return
    if args.load:
        write_results(json.loads(args.load.read_text()), args.note)
        return
    after = HERE.parent.parent / "backend"
    codes = [("after", after), *([("before", args.before)] if args.before else [])]
    results = []
    for _ in range(args.rounds):
        for nice in args.nice:
            for code, backend in codes:
                found = spawn(code if args.before else "this code", backend, nice, args.seconds, args.period_ms)
                print(json.dumps({k: v for k, v in found.items() if k != "restored"}), flush=True)
                results.append(found)
    results = sorted(results, key=lambda found: (found["code"], found["nice"]))
    if args.save:
        args.save.write_text(json.dumps(results))
    if not args.no_write:
        write_results(results, args.note)


if __name__ == "__main__":
    main()
