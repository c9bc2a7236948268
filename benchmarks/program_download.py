"""Program download speed (issue 32): a 256 KiB image by SDO block transfer to the simulated servo (node 7 of the demo
plant), through the real API and job, against the theoretical rate of the session's bit rate.

The theoretical time is the sum of the exact bits of every frame the transfer put on the bus (the same count
services/monitoring uses: ``transport.busload.frame_bits``, stuff bits of the actual data and the intermission
included) divided by the bit rate; the theoretical rate is the image's bytes over that time. The python-can virtual
bus does not pace frames at a bit rate, so the measured rate says whether DriveBench (client, job, simulator) keeps up
with a real bus at that rate: at >= 100 % the wire would be the limit, not the tool.

The benchmark follows the job on its progress socket (``/ws/jobs/{id}``), as the page does. Every round runs in a
fresh process; with ``--before DIR`` (the ``backend`` folder of an export of the code to compare with, e.g.
``git archive main backend | tar -x -C /tmp/before``) the rounds of that code and of this one alternate, so both
see the same load.

    .venv/bin/python benchmarks/program_download.py [--before /tmp/before/backend]   # prints, writes RESULTS.md
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HEADING = "## Program download"
HERE = Path(__file__).resolve().parent
BACKEND = HERE.parent / "backend"
NODE = 7
SIZE = 256 * 1024
ROUNDS = 2
BITRATES = (125_000, 250_000, 500_000, 1_000_000)
TARGET = 70.0


DEFINITION = (
    "Share = measured rate / theoretical rate. Theoretical: the image's bytes over the wire time of the frames the "
    "transfer put on the bus (block initiate to end response, both directions), each frame's exact bits as the monitor "
    "counts them (`transport.busload.frame_bits`: stuff bits of its actual data, CRC, intermission) at the session's "
    "bit rate; no time for the device's turnaround. Measured: the image's bytes over the time from the first to the "
    "last of those frames as a listener on the bus saw them. The python-can virtual bus has no bit time: nothing "
    "paces the frames (the sender does not pace either; on a real adapter its transmit queue would), so the share "
    "says how far DriveBench (client, job, simulated drive, all in one process) is ahead of or behind a real wire at "
    "that rate, and is over 100 % wherever the tool would not be the limit.")


def one_round(bitrate: int) -> dict[str, Any]:
    """One download in this process (the code on ``sys.path``): frames, wire time and measured rate."""
    import can
    from fastapi.testclient import TestClient

    from drivebench.config import REPO_ROOT
    from drivebench.transport.busload import frame_bits
    from drivebench.web.app import create_app

    channel = f"bench-program-{time.time_ns()}"
    # settle_heap as `drivebench serve` does (a process of its own): without it every full collection walks the
    # ~250,000 objects of start-up again, up to a second on a loaded machine with every thread standing still, and
    # the simulated drive drops the transfer (its SDO server's 1 s timeout)
    app = create_app(plant_file=REPO_ROOT / "plants" / "demo.json", plant_bus=f"virtual:{channel}@{bitrate}",
                     latency="0ms", settle_heap=True)
    spy = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    base = f"/api/sessions/demo-plant/nodes/{NODE}/program"
    try:
        with TestClient(app, base_url="http://127.0.0.1") as client:
            image = b"\x7f" + os.urandom(SIZE - 1)  # a first byte ':' would read as Intel HEX
            checked = client.post(base + "/check", files={"file": ("bench.bin", image)})
            if checked.status_code != 200:
                return {"failed": True, "error": f"check: {checked.status_code} {checked.text[:200]}"}
            file_id = checked.json()["file_id"]
            while spy.recv(timeout=0.05) is not None:
                pass
            body = {"file_id": file_id}
            cpu_before = time.process_time()
            first = client.post(base + "/download", json=body)
            if first.status_code == 428:
                problem = first.json()
                first = client.post(base + "/download", json={**body, "confirm": problem["confirm_node"],
                                                              "confirm_values": problem["confirm_values"]})
            job = first.json()
            if first.status_code != 202:
                return {"failed": True, "error": f"download: {first.status_code} {first.text[:200]}"}
            with client.websocket_connect("ws://127.0.0.1" + job["links"]["progress"]) as socket:
                while socket.receive_json()["state"] == "running":
                    pass
            cpu_s = time.process_time() - cpu_before
            now = client.get(f"{base}/jobs/{job['id']}").json()
            frames = []
            while (frame := spy.recv(timeout=0.2)) is not None:
                frames.append(frame)
            if now["state"] != "done" or now["result"].get("transfer") != "block":
                return {"failed": True, "error": f"{now['error']} (longest pause between two frames of the client: "
                                                 f"{_longest_pause(frames):.2f} s)"}
    finally:
        spy.shutdown()
    # the 0x1F50 transfer: from its block initiate (0xC6 ... 0x1F50) to the end response (0xA1)
    sdo = [f for f in frames if f.arbitration_id in (0x600 + NODE, 0x580 + NODE)]
    start = next(i for i, f in enumerate(sdo) if f.data[0] == 0xC6 and f.data[1:3] == b"\x50\x1f")
    end = next(i for i, f in enumerate(sdo) if i > start and f.arbitration_id == 0x580 + NODE and f.data[0] == 0xA1)
    transfer = sdo[start:end + 1]
    bits = sum(frame_bits(f.arbitration_id, bytes(f.data)) for f in transfer)
    wire_s = bits / bitrate
    measured_s = transfer[-1].timestamp - transfer[0].timestamp
    return {"frames": len(transfer), "bits": bits, "wire_s": wire_s, "measured_s": measured_s,
            "job_s": float(now["progress"]["elapsed_s"]), "theoretical": SIZE / wire_s, "measured": SIZE / measured_s,
            "cpu_us_per_frame": 1e6 * cpu_s / len(transfer), "load": os.getloadavg()[0]}


def _longest_pause(frames: list[Any]) -> float:
    """Where a round fails: the simulated drive drops a transfer after 1 s without a frame (its SDO server timeout)."""
    sent = [f.timestamp for f in frames if f.arbitration_id == 0x600 + NODE]
    return max((b - a for a, b in itertools.pairwise(sent)), default=0.0)


def in_process(bitrate: int, backend: Path) -> dict[str, Any]:
    """One round in a fresh interpreter with ``backend`` first on the path."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(backend), str(HERE)])}
    done = subprocess.run([sys.executable, __file__, "--round", str(bitrate)], env=env, capture_output=True,
                          text=True, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode or not lines:
        return {"failed": True, "error": (done.stderr.strip().splitlines() or ["no output"])[-1]}
    result: dict[str, Any] = json.loads(lines[-1])
    return result


def _cpu(runs: list[dict[str, Any]]) -> str:
    """The whole process's CPU time during the job (app, plant, this script) per frame of the transfer."""
    known = [run["cpu_us_per_frame"] for run in runs if "cpu_us_per_frame" in run]
    return f"{statistics.median(known):.0f} µs" if known else "-"


def table(title: str, results: dict[int, list[dict[str, Any]]]) -> tuple[list[str], float, list[str]]:
    lines = [f"{title}:", "",
             "| Bit rate | Frames | Wire time (exact bits) | Theoretical | Measured (best / median) | Share (best / "
             "median) | Job total | CPU per frame (median) |",
             "|---|---|---|---|---|---|---|---|"]
    worst = 100_000.0
    failed = []
    for bitrate, every in results.items():
        runs = [run for run in every if not run.get("failed")]
        failed.extend(f"{bitrate // 1000} kbit/s: {run['error']}" for run in every if run.get("failed"))
        if not runs:
            worst = 0.0
            continue
        best = max(runs, key=lambda run: run["measured"])
        median = statistics.median(run["measured"] for run in runs)
        share, median_share = (100 * rate / best["theoretical"] for rate in (best["measured"], median))
        worst = min(worst, share)
        lines.append(f"| {bitrate // 1000} kbit/s | {best['frames']} | {best['wire_s']:.2f} s "
                     f"| {best['theoretical'] / 1024:.1f} KiB/s | {best['measured'] / 1024:.1f} / "
                     f"{median / 1024:.1f} KiB/s | **{share:.0f} %** / {median_share:.0f} % | {best['job_s']:.2f} s "
                     f"| {_cpu(runs)} |")
    return lines, worst, failed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--round", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--before", type=Path, help="backend folder of the code to compare with")
    parser.add_argument("--rounds", type=int, default=ROUNDS)
    parser.add_argument("--bitrates", default=",".join(str(b) for b in BITRATES))
    parser.add_argument("--no-write", action="store_true", help="print only, leave RESULTS.md alone")
    args = parser.parse_args()
    if args.round:
        print(json.dumps(one_round(args.round)))
        return
    bitrates = [int(b) for b in args.bitrates.split(",")]
    trees = {"this code": BACKEND, **({"before": args.before} if args.before else {})}
    results: dict[str, dict[int, list[dict[str, Any]]]] = {name: {b: [] for b in bitrates} for name in trees}
    loads = []
    for bitrate in bitrates:
        for _ in range(args.rounds):
            for name, backend in trees.items():
                run = in_process(bitrate, backend)
                results[name][bitrate].append(run)
                loads.append(os.getloadavg()[0])
                print(name, bitrate, {k: round(v, 3) if isinstance(v, float) else v for k, v in run.items()},
                      flush=True)
    lines = [
        f"`benchmarks/program_download.py{' --before ...' if args.before else ''}`, "
        f"{time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC on {platform.node()} ({platform.machine()}, Python "
        f"{platform.python_version()}, {os.cpu_count()} cores, load average {min(loads):.1f} ... {max(loads):.1f} "
        f"during the run); demo plant on a python-can virtual bus, node 7 (generic servo, block size 127), "
        f"{SIZE // 1024} KiB random image through the API job (check, stop, 0x1F50 block download, start, 0x1F56), "
        f"followed on the job's progress socket; {args.rounds} rounds per bit rate"
        + (", each in a fresh process, the rounds of the two versions alternating." if args.before else
           ", each in a fresh process."),
    ]
    lines += ["", DEFINITION]
    verdicts = []
    for name, per_bitrate in reversed(results.items()):
        rows, worst, failed = table(f"**{name}**", per_bitrate)
        lines += ["", *rows]
        if failed:
            lines += ["", f"Rounds that failed ({len(failed)}): " + "; ".join(failed)]
        verdicts.append(f"{name}: {'met' if worst >= TARGET else 'NOT met'} (lowest best-round share {worst:.0f} %)")
    lines += ["", f"Target: >= {TARGET:.0f} % of the theoretical rate at the session's bit rate. "
                  + "; ".join(verdicts) + "."]
    body = "\n".join(lines)
    print(body)
    if not args.no_write:
        sys.path.insert(0, str(HERE))
        from _monitor_results import write_section

        write_section(HEADING, body)


if __name__ == "__main__":
    main()
