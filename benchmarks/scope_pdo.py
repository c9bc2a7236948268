"""Scope sampling by PDO (issue 31): 4 channels from 2 nodes of the demo plant (node 7: 0x6064, 0x606C; node 3:
0x6041, 0x6044) at a 1 ms SYNC for 60 s (``--seconds`` to shorten). A second python-can bus on the virtual channel
counts what went over the bus.

Reported: SYNCs sent and frames delivered; TPDO frames sent by the drives and samples received (a channel value in
a delivered frame); the bus load of everything on the wire (exact frame bits, as the monitor counts them); CPU of
the process per 1,000 channel samples/s; memory (RSS growth during the recording).

The simulated drives run in the same process as the recording (a virtual bus does not leave the process), so the
CPU figure is that of the server side and the simulated plant together: an upper bound for the server.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import sys
import threading
import time
from pathlib import Path

import can

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _monitor_results import machine

from drivebench.config import REPO_ROOT
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.control.drive_guard import Confirmation
from drivebench.services.params.write_context import LOCAL_USER, WriteContext
from drivebench.services.scope import pdo_source
from drivebench.services.scope.pdo_plan import plan_recording
from drivebench.services.scope.pdo_source import PdoScopeSource
from drivebench.services.scope.source import ScopeChannel, ScopeFrame
from drivebench.services.session_manager import SessionManager
from drivebench.services.storage import database
from drivebench.simulator.plant import Plant, PlantFile
from drivebench.transport.busload import message_bits

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
HEADING = "## Scope: sampling by PDO"
CHANNELS = [ScopeChannel(7, "0x6064"), ScopeChannel(7, "0x606C"), ScopeChannel(3, "0x6041"), ScopeChannel(3, "0x6044")]
BITRATE = 500_000


def cpu_seconds() -> float:
    fields = Path(f"/proc/{os.getpid()}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_kib() -> int:
    for line in Path(f"/proc/{os.getpid()}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


class Wire(can.Listener):
    def __init__(self) -> None:
        self.bits = 0
        self.syncs = 0
        self.tpdos = 0
        self.cobs: set[int] = set()

    def on_message_received(self, msg: can.Message) -> None:
        self.bits += message_bits(msg)
        if msg.arbitration_id == 0x080:
            self.syncs += 1
        elif msg.arbitration_id in self.cobs:
            self.tpdos += 1


async def record(seconds: float, period_s: float, db_url: str) -> dict[str, float]:
    channel = f"scope-bench-{os.getpid()}"
    registry = ProfileRegistry()
    plant = Plant(PlantFile.load(REPO_ROOT / "plants" / "demo.json"), registry.get,
                  bus=f"virtual:{channel}@{BITRATE}", latency="0ms").start()
    wire_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    wire = Wire()
    notifier = can.Notifier(wire_bus, [wire])
    manager = SessionManager(registry, sdo_timeout_s=1.0, sdo_retries=1)
    try:
        session = await manager.open(plant.spec, "scope-bench")
        for node in plant.nodes.values():
            session.add_node(node.node_id, node.profile.id)
        plan = await plan_recording(session, CHANNELS, period_s)
        wire.cobs = {tpdo.cob_id for tpdo in plan.tpdos}
        needed = pdo_source.confirmation(plan)
        assert needed is not None
        ctx = WriteContext.internal(user=LOCAL_USER, origin="benchmark").confirming(
            Confirmation(needed[0] if needed[0] is not None else "all", needed[2]))
        source = PdoScopeSource(session, plan, ctx, db_url=db_url)
        counts = {"frames": 0, "samples": 0}

        def on_frame(frame: ScopeFrame) -> None:
            counts["frames"] += 1
            counts["samples"] += sum(value is not None for value in frame.raw)

        events: list[str] = []
        await source.start(on_frame, lambda event: events.append(event.text))
        await asyncio.sleep(1.0)  # the nodes started, the TPDOs flowing
        frames0, samples0, bits0, syncs0, tpdos0 = (counts["frames"], counts["samples"], wire.bits, wire.syncs,
                                                    wire.tpdos)
        cpu0, rss0, t0 = cpu_seconds(), rss_kib(), time.monotonic()
        await asyncio.sleep(seconds)
        elapsed = time.monotonic() - t0
        cpu, rss = cpu_seconds() - cpu0, rss_kib() - rss0
        frames, samples = counts["frames"] - frames0, counts["samples"] - samples0
        bits, syncs, tpdos = wire.bits - bits0, wire.syncs - syncs0, wire.tpdos - tpdos0
        texts = await source.stop()
        return {"seconds": elapsed, "period_ms": source.period_s * 1000, "syncs": syncs, "frames": frames,
                "tpdos": tpdos, "samples": samples, "expected_samples": tpdos * 2, "load": 100 * bits / (
                    elapsed * BITRATE), "cpu_percent": 100 * cpu / elapsed, "rss_kib": rss,
                "late": source.late, "extra": source.extra, "events": len(events),
                "restored": all("read back as before" in t or "mean period" in t or "pre-operational" in t
                                for t in texts)}
    finally:
        await manager.close_all()
        notifier.stop()
        wire_bus.shutdown()
        plant.stop()


def write_results(result: dict[str, float], seconds: float) -> None:
    per_k = result["cpu_percent"] / (result["samples"] / result["seconds"] / 1000)
    received = f'{result["tpdos"]} / {result["samples"]} of {result["expected_samples"]}'
    cpu = f'{result["cpu_percent"]:.1f} % of one core = {per_k:.1f} % per 1,000 samples/s'
    body = f"""{HEADING}

Written by `benchmarks/scope_pdo.py`: {len(CHANNELS)} channels from 2 nodes of the demo plant (node 7: 0x6064, 0x606C
in TPDO3; node 3: 0x6041, 0x6044 in TPDO5) at a 1 ms SYNC for {seconds:g} s, after 1 s of start. Machine: {machine()},
shared with other work; {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}.

| Measure | Value |
|---|---|
| SYNC: sent / mean period reached | {result["syncs"]} / {result["period_ms"]:.3f} ms |
| Frames delivered (one per SYNC) | {result["frames"]} |
| TPDO frames the drives sent / channel samples received (2 per frame) | {received} |
| Frames late or extra (not delivered) | {result["late"]} / {result["extra"]} |
| Bus load (everything on the wire, exact frame bits) | {result["load"]:.1f} % (target < 80 %) |
| CPU of the process (recording + simulated plant) | {cpu} |
| Memory: RSS growth of the process during the recording | {result["rss_kib"]} KiB |
| Events / everything read back as before after stop | {result["events"]} / {"yes" if result["restored"] else "NO"} |

The simulated drives run in this process (a virtual bus does not leave it), so the CPU is an upper bound for the
server. A shortfall of SYNCs against {seconds * 1000:g} is the producer thread on a loaded machine: it does not burst to
catch up (each pause over 20 ms is an event), and the mean period above is what the samples' time base uses.
"""
    text = RESULTS.read_text(encoding="utf-8")
    if HEADING in text:
        start = text.index(HEADING)
        following = re.search(r"^## ", text[start + len(HEADING):], flags=re.MULTILINE)
        end = start + len(HEADING) + following.start() if following else len(text)
        text = text[:start] + body + ("\n" + text[end:] if following else "")
    else:
        text = text.rstrip("\n") + "\n\n" + body
    RESULTS.write_text(text, encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--period-ms", type=float, default=1.0)
    args = parser.parse_args()
    db_file = Path(f"/tmp/scope-bench-{os.getpid()}.db")
    db_url = f"sqlite:///{db_file}"
    database.upgrade_to_head(db_url)
    try:
        result = asyncio.run(record(args.seconds, args.period_ms / 1000, db_url))
    finally:
        database.dispose(db_url)
        db_file.unlink(missing_ok=True)
    print(result)
    write_results(result, args.seconds)
    print(f"threads left: {threading.active_count()}")


if __name__ == "__main__":
    main()
