"""Program download speed (issue 32): a 256 KiB image by SDO block transfer to the simulated servo (node 7 of the demo
plant), through the real API and job, against the theoretical rate of the session's bit rate.

The theoretical time is the sum of the exact bits of every frame the transfer put on the bus (the same count
services/monitoring uses: ``transport.busload.frame_bits``, stuff bits of the actual data and the intermission
included) divided by the bit rate; the theoretical rate is the image's bytes over that time. The python-can virtual
bus does not pace frames at a bit rate, so the measured rate says whether DriveBench (client, job, simulator) keeps up
with a real bus at that rate: at >= 100 % the wire would be the limit, not the tool.

    .venv/bin/python benchmarks/program_download.py          # prints the table and writes RESULTS.md
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from typing import Any

import can
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from drivebench.transport.busload import frame_bits
from drivebench.web.app import create_app

from _monitor_results import write_section  # isort: skip  (beside this script)

HEADING = "## Program download"
DEMO_PLANT = REPO_ROOT / "plants" / "demo.json"
NODE = 7
SIZE = 256 * 1024
ROUNDS = 2
BITRATES = (125_000, 250_000, 500_000, 1_000_000)
TARGET = 70.0


def _confirmed(client: TestClient, url: str, body: dict[str, Any]) -> Any:
    first = client.post(url, json=body)
    if first.status_code != 428:
        return first
    problem = first.json()
    return client.post(url, json={**body, "confirm": problem["confirm_node"],
                                  "confirm_values": problem["confirm_values"]})


def one_round(bitrate: int) -> dict[str, float]:
    channel = f"bench-program-{time.time_ns()}"
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@{bitrate}", latency="0ms")
    spy = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    base = f"/api/sessions/demo-plant/nodes/{NODE}/program"
    try:
        with TestClient(app, base_url="http://127.0.0.1") as client:
            image = os.urandom(SIZE)
            file_id = client.post(base + "/check", files={"file": ("bench.bin", image)}).json()["file_id"]
            while spy.recv(timeout=0.05) is not None:
                pass
            job = _confirmed(client, base + "/download", {"file_id": file_id}).json()
            while (now := client.get(f"{base}/jobs/{job['id']}").json())["state"] == "running":
                time.sleep(0.05)
            if now["state"] != "done" or now["result"].get("transfer") != "block":
                return {"failed": 1.0, "error": now["error"]}  # type: ignore[dict-item]
            frames = []
            while (frame := spy.recv(timeout=0.2)) is not None:
                frames.append(frame)
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
    job_s = float(now["progress"]["elapsed_s"])
    return {"frames": len(transfer), "bits": bits, "wire_s": wire_s, "measured_s": measured_s, "job_s": job_s,
            "theoretical": SIZE / wire_s, "measured": SIZE / measured_s}


def main() -> None:
    rows = []
    failed: list[str] = []
    for bitrate in BITRATES:
        every = [one_round(bitrate) for _ in range(ROUNDS)]
        runs = [run for run in every if "failed" not in run]
        failed.extend(f"{bitrate // 1000} kbit/s: {run['error']}" for run in every if "failed" in run)
        if runs:
            best = max(runs, key=lambda run: run["measured"])
            rows.append((bitrate, best, statistics.median(run["measured"] for run in runs)))
    load = os.getloadavg()[0]
    lines = [
        f"`benchmarks/program_download.py`, {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC on "
        f"{platform.node()} ({platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} cores, "
        f"load average {load:.1f}); demo plant on a python-can virtual bus, node 7 (generic servo, block size 127), "
        f"{SIZE // 1024} KiB random image through the API job (check, stop, 0x1F50 block download, start, 0x1F56), "
        f"best of {ROUNDS} rounds per bit rate.",
        "",
        "| Bit rate | Frames | Wire time (exact bits) | Theoretical | Measured (best / median) | Share | Job total |",
        "|---|---|---|---|---|---|---|",
    ]
    for bitrate, best, median in rows:
        share = 100 * best["measured"] / best["theoretical"]
        lines.append(f"| {bitrate // 1000} kbit/s | {best['frames']} | {best['wire_s']:.2f} s "
                     f"| {best['theoretical'] / 1024:.1f} KiB/s | {best['measured'] / 1024:.1f} / "
                     f"{median / 1024:.1f} KiB/s | **{share:.0f} %** | {best['job_s']:.2f} s |")
    worst = min((100 * best["measured"] / best["theoretical"] for _, best, _ in rows), default=0.0)
    lines += ["", f"Target: >= {TARGET:.0f} % of the theoretical rate at the session's bit rate: "
                  f"{'met' if worst >= TARGET else 'NOT met'} (lowest share {worst:.0f} %)."]
    if failed:
        lines += ["", f"Rounds that failed ({len(failed)} of {ROUNDS * len(BITRATES)}): " + "; ".join(failed)]
    body = "\n".join(lines)
    print(body)
    write_section(HEADING, body)


if __name__ == "__main__":
    main()
