"""The request path (issue 21), printed and written to RESULTS.md under '## Request path'.

Three processes share one bus through a `drivebench hub` (socketcand protocol): `drivebench simulate` (a plain
CANopen slave, node 5, 8400 motec profile, no added latency), `drivebench serve --bus` (the server under test) and
this process, whose canopen RemoteNode reads the same objects on the same bus. Rounds alternate which path goes
first, so the load of a shared machine hits both alike; every ratio is the median of the rounds' ratios.

(a) single expedited read (0x1017.0): REST GET, one keep-alive client, vs canopen `sdo.upload` (target >= 0.5)
(b) 100 refs: one REST batch read (`POST …/parameters:read`) vs canopen reading the same 100 in a loop (>= 0.9)
(c) segmented read (C00099 = 0x5F9C.0, firmware version string): REST GET vs canopen `sdo.upload` (>= 0.8)
(d) `GET /api/health`: one keep-alive client, requests/s (>= 3,000); 20 concurrent clients, p99 (< 5 ms)
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import canopen
import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _monitor_results import machine  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
HEADING = "## Request path"
NODE = 5
PROFILE = "lenze-8400-motec-canopen"
ROUNDS = 15
EXE = str(Path(sys.executable).with_name("drivebench"))


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _wait(check: Callable[[], bool], timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if check():
                return
        except (OSError, httpx.HTTPError):
            pass
        time.sleep(0.2)
    raise TimeoutError("a benchmark process did not come up")


class KeepAlive:
    """A minimal HTTP/1.1 keep-alive client on one socket: the figures are the server's, not a client library's
    (httpx spends about as long per request in Python as the server does)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buffer = b""

    def request(self, method: str, path: str, body: bytes = b"") -> bytes:
        head = f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: {len(body)}\r\n"
        if body:
            head += "Content-Type: application/json\r\n"
        self.sock.sendall(head.encode() + b"\r\n" + body)
        while b"\r\n\r\n" not in self.buffer:
            self.buffer += self._recv()
        header, _, rest = self.buffer.partition(b"\r\n\r\n")
        if not header.startswith(b"HTTP/1.1 2"):
            raise RuntimeError(header.split(b"\r\n")[0].decode())
        length = next(int(line.split(b":")[1]) for line in header.split(b"\r\n")
                      if line.lower().startswith(b"content-length:"))
        while len(rest) < length:
            rest += self._recv()
        self.buffer = rest[length:]
        return rest[:length]

    def _recv(self) -> bytes:
        chunk = self.sock.recv(65536)
        if not chunk:
            raise ConnectionError("the server closed the connection")
        return chunk

    def close(self) -> None:
        self.sock.close()


def _port_open(port: int) -> bool:
    with socket.create_connection(("127.0.0.1", port), timeout=1):
        return True


def _median_ratio(pairs: list[tuple[float, float]]) -> float:
    """Rounds of (canopen seconds, DriveBench seconds) for the same work: DriveBench's speed / canopen's."""
    return statistics.median(raw / ours for raw, ours in pairs)


def _settled(work: Callable[[], float]) -> float:
    """Both clients use the node's one SDO channel and each hears the other's answers: a pause before a round lets
    the hub deliver the last answer of the other path first (canopen would take a late one for its own)."""
    time.sleep(0.1)
    return work()


def _rounds(canopen_round: Callable[[], float], ours_round: Callable[[], float]) -> list[tuple[float, float]]:
    pairs = []
    for number in range(ROUNDS):
        if number % 2:
            ours = _settled(ours_round)
            raw = _settled(canopen_round)
        else:
            raw = _settled(canopen_round)
            ours = _settled(ours_round)
        pairs.append((raw, ours))
    return pairs


def _timed(work: Callable[[], object], times: int) -> float:
    started = time.perf_counter()
    for _ in range(times):
        work()
    return time.perf_counter() - started


async def _health_client(port: int, per_client: int, latencies: list[float]) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    request = b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    for number in range(per_client + 1):
        started = time.perf_counter()
        writer.write(request)
        head = await reader.readuntil(b"\r\n\r\n")
        if not head.startswith(b"HTTP/1.1 200"):
            raise RuntimeError(head.decode(errors="replace"))
        length = next(int(line.split(b":", 1)[1]) for line in head.split(b"\r\n")
                      if line.lower().startswith(b"content-length:"))
        await reader.readexactly(length)
        if number:  # the first one opens the connection
            latencies.append((time.perf_counter() - started) * 1000)
    writer.close()


def _health_concurrent(port: int, clients: int, per_client: int) -> list[float]:
    """``clients`` keep-alive connections, each one request at a time, from one asyncio loop: a thread per client
    measured Python's GIL hand-overs (5 ms switch interval) more than the server."""
    latencies: list[float] = []

    async def run() -> None:
        await asyncio.gather(*(_health_client(port, per_client, latencies) for _ in range(clients)))

    asyncio.run(run())
    return sorted(latencies)


def measure(workdir: Path) -> dict[str, Any]:
    hub_port, http_port = _free_port(), _free_port()
    bus_spec = f"socketcand:127.0.0.1:{hub_port}/can0"
    plant = workdir / "plant.json"
    plant.write_text(json.dumps({"name": "bench", "nodes": [{"node_id": NODE, "profile": PROFILE}]}))
    env = {**os.environ, "DRIVEBENCH_DATA_DIR": str(workdir / "var")}
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    children = [subprocess.Popen([EXE, "hub", "--port", str(hub_port)], **quiet)]  # type: ignore[call-overload]
    try:
        _wait(lambda: _port_open(hub_port))
        children.append(subprocess.Popen([EXE, "simulate", "--bus", bus_spec, "--plant", str(plant),
                                          "--latency", "0ms"], **quiet))  # type: ignore[call-overload]
        children.append(subprocess.Popen([EXE, "serve", "--port", str(http_port), "--bus", bus_spec],
                                         **quiet))  # type: ignore[call-overload]
        url = f"http://127.0.0.1:{http_port}"
        http = httpx.Client(base_url=url, timeout=30)
        _wait(lambda: http.get("/api/health").status_code == 200)
        session = http.get("/api/sessions").json()[0]["id"]
        http.post(f"/api/sessions/{session}/nodes", json={"node_id": NODE, "profile_id": PROFILE}).raise_for_status()
        base = f"/api/sessions/{session}/nodes/{NODE}"
        _wait(lambda: http.get(base + "/parameters/0x1017.0").status_code == 200)

        listed = http.get(base + "/parameters").json()["parameters"]
        readable = [p for p in listed if p["access"] in ("ro", "rw", "const") and p["data_type"] not in
                    ("DOMAIN", "VISIBLE_STRING", "OCTET_STRING", "UNICODE_STRING")]
        hundred = readable[:100]
        addresses = [(int(p["index"], 16), p["subindex"]) for p in hundred]
        refs = [p["ref"] for p in hundred]
        batch_body = json.dumps({"refs": refs}).encode()
        lean = KeepAlive(http_port)
        first = http.post(base + "/parameters:read", json={"refs": refs}).json()["items"]
        failed = [item["ref"] for item in first if not item["ok"]]

        bus = can.Bus(interface="socketcand", channel="can0", host="127.0.0.1", port=hub_port)
        network = canopen.Network(bus)
        notifier = can.Notifier(bus, network.listeners, 1)
        network.notifier = notifier
        node = network.add_node(NODE, canopen.ObjectDictionary())
        try:
            for index, subindex in addresses:  # every ref the batch reads, canopen can read too
                node.sdo.upload(index, subindex)
            single = _rounds(lambda: _timed(lambda: node.sdo.upload(0x1017, 0), 100),
                             lambda: _timed(lambda: lean.request("GET", base + "/parameters/0x1017.0"), 100))
            load_a = os.getloadavg()[0]
            batch = _rounds(lambda: _timed(lambda: [node.sdo.upload(i, s) for i, s in addresses], 1),
                            lambda: _timed(lambda: lean.request("POST", base + "/parameters:read", batch_body), 1))
            load_b = os.getloadavg()[0]
            segmented = _rounds(lambda: _timed(lambda: node.sdo.upload(0x5F9C, 0), 30),
                                lambda: _timed(lambda: lean.request("GET", base + "/parameters/C00099"), 30))
            load_c = os.getloadavg()[0]
        finally:
            notifier.stop()
            bus.shutdown()

        for _ in range(200):
            lean.request("GET", "/api/health")
        health_rates = [2000 / _timed(lambda: lean.request("GET", "/api/health"), 2000) for _ in range(3)]
        load_d = os.getloadavg()[0]
        concurrent = _health_concurrent(http_port, 20, 200)
        load_e = os.getloadavg()[0]
        http.close()
        lean.close()
    finally:
        for child in reversed(children):
            child.terminate()
            child.wait(timeout=20)
    return {
        "single": single, "batch": batch, "segmented": segmented, "failed": failed, "loads": {
            "a": load_a, "b": load_b, "c": load_c, "d": load_d, "e": load_e},
        "health_per_s": statistics.median(health_rates),
        "p50": concurrent[len(concurrent) // 2], "p99": concurrent[int(len(concurrent) * 0.99) - 1],
        "samples": len(concurrent),
    }


def _rate(pairs: list[tuple[float, float]], which: int, work: int) -> float:
    return work / statistics.median(pair[which] for pair in pairs)


def table(r: dict[str, Any]) -> str:
    loads = r["loads"]
    single, batch, segmented = (_median_ratio(r[k]) for k in ("single", "batch", "segmented"))
    rows = [
        ("(a) single read 0x1017.0, REST vs canopen", f"{_rate(r['single'], 1, 100):.0f}/s vs "
         f"{_rate(r['single'], 0, 100):.0f}/s = **{single:.2f}**", ">= 0.5", single >= 0.5, loads["a"]),
        ("(b) 100 refs: one batch request vs canopen loop", f"{_rate(r['batch'], 1, 100):.0f}/s vs "
         f"{_rate(r['batch'], 0, 100):.0f}/s = **{batch:.2f}**", ">= 0.9", batch >= 0.9, loads["b"]),
        ("(c) segmented read C00099 (0x5F9C.0), REST vs canopen", f"{_rate(r['segmented'], 1, 30):.0f}/s vs "
         f"{_rate(r['segmented'], 0, 30):.0f}/s = **{segmented:.2f}**", ">= 0.8", segmented >= 0.8, loads["c"]),
        ("(d) `/api/health`, one keep-alive client", f"**{r['health_per_s']:.0f}/s**", ">= 3,000/s",
         r["health_per_s"] >= 3000, loads["d"]),
        (f"(d) `/api/health`, 20 clients ({r['samples']} requests): p50 / p99",
         f"{r['p50']:.1f} / **{r['p99']:.1f} ms**", "p99 < 5 ms", r["p99"] < 5, loads["e"]),
    ]
    lines = ["| Figure | Measured | Target | Met | Load average (1 min) |", "|---|---|---|---|---|"]
    lines += [f"| {name} | {value} | {target} | {'yes' if met else '**no**'} | {load:.1f} |"
              for name, value, target, met, load in rows]
    if r["failed"]:
        lines.append(f"\nRefs of the batch that answered with an error (counted in both paths): {r['failed']}")
    return "\n".join(lines)


def write_results(body: str) -> None:
    text = RESULTS.read_text(encoding="utf-8") if RESULTS.exists() else ""
    section = (f"{HEADING}\n\n{machine()}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. Hub, slave, server "
               f"and this client are four processes on the same 2 cores; each ratio is the median of {ROUNDS} "
               "interleaved rounds (benchmarks/request_path.py).\n\n" + body + "\n")
    start = text.find(f"\n{HEADING}\n")  # the whole line: '## Request path: where …' is another section
    if start < 0:
        text = text.rstrip() + "\n\n" + section
    else:
        end = text.find("\n## ", start + len(HEADING))
        text = text[:start + 1] + section + (text[end:] if end >= 0 else "")
    RESULTS.write_text(text, encoding="utf-8")


def main() -> None:
    with tempfile.TemporaryDirectory() as workdir:
        result = measure(Path(workdir))
    body = table(result)
    print(body)
    if "--no-write" not in sys.argv:
        write_results(body)


if __name__ == "__main__":
    main()
