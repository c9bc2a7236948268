"""Shared by the benchmarks: the machine line, a mixed CANopen trace (monitor_*.py), and writing a part of
RESULTS.md (a ``## `` section of its own, or a subsection under ``## Monitor``).

Each script owns one ``### Monitor: ...`` subsection under ``## Monitor`` and rewrites only that.
"""

from __future__ import annotations

import os
import platform
import random
import re
from pathlib import Path

import can

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
HEADING = "## Monitor"


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def write_subsection(title: str, body: str) -> None:
    """Replace (or add) ``### Monitor: {title}`` inside the ``## Monitor`` section of RESULTS.md."""
    text = RESULTS.read_text(encoding="utf-8") if RESULTS.exists() else "# Benchmark results\n"
    sub = f"### Monitor: {title}"
    block = f"{sub}\n\n{body.strip()}\n"
    if HEADING not in text:
        text = text.rstrip("\n") + f"\n\n{HEADING}\n\nWritten by `benchmarks/monitor_*.py`.\n"
    start = text.index(HEADING)
    following = re.search(r"^## ", text[start + len(HEADING):], flags=re.MULTILINE)
    end = start + len(HEADING) + following.start() if following else len(text)
    section = text[start:end]
    if sub in section:
        sub_start = section.index(sub)
        next_sub = re.search(r"^### ", section[sub_start + len(sub):], flags=re.MULTILINE)
        sub_end = sub_start + len(sub) + next_sub.start() if next_sub else len(section)
        section = section[:sub_start] + block + ("\n" if next_sub else "") + section[sub_end:]
    else:
        section = section.rstrip("\n") + "\n\n" + block
    text = text[:start] + section.rstrip("\n") + "\n" + ("\n" + text[end:] if text[end:] else "")
    RESULTS.write_text(text, encoding="utf-8")


def mixed_trace(count: int, seed: int = 7) -> list[can.Message]:
    """A commissioning-like mix on nodes 1..20: TPDO/RPDO with changing process data (most of the load), SYNC,
    heartbeats, SDO request/response pairs, EMCY, NMT, a few LSS, 29-bit and error frames."""
    rng = random.Random(seed)
    nodes = list(range(1, 21))
    frames: list[can.Message] = []
    t = 0.0

    def add(cob_id: int, data: bytes, **kwargs: object) -> None:
        nonlocal t
        t += 0.0001
        frames.append(can.Message(timestamp=t, arbitration_id=cob_id, data=data,
                                  is_extended_id=bool(kwargs.pop("extended", False)), **kwargs))  # type: ignore[arg-type]

    while len(frames) < count:
        roll = rng.random()
        node = rng.choice(nodes)
        if roll < 0.60:
            base = rng.choice((0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500))
            add(base + node, rng.randbytes(rng.choice((2, 4, 6, 8))))
        elif roll < 0.68:
            add(0x080, b"")
        elif roll < 0.80:
            add(0x700 + node, bytes([rng.choice((0x05, 0x7F, 0x04))]))
        elif roll < 0.96:
            index = rng.randrange(0x1000, 0x6000)
            add(0x600 + node, bytes([0x40, index & 0xFF, index >> 8, 0, 0, 0, 0, 0]))
            add(0x580 + node, bytes([0x43, index & 0xFF, index >> 8, 0]) + rng.randbytes(4))
        elif roll < 0.97:
            add(0x080 + node, bytes.fromhex("1032110000000000"))
        elif roll < 0.975:
            add(0x000, bytes([0x01, node]))
        elif roll < 0.98:
            add(0x7E5, bytes([0x5E, 0, 0, 0, 0, 0, 0, 0]))
        elif roll < 0.999:
            add(0x18FF0000 + node, rng.randbytes(8), extended=True)
        else:
            add(0x004, bytes(8), is_error_frame=True, extended=True)
    return frames[:count]


def write_section(heading: str, body: str) -> None:
    """Replace (or add at the end) the ``## `` section ``heading`` of RESULTS.md with ``body``."""
    text = RESULTS.read_text(encoding="utf-8") if RESULTS.exists() else "# Benchmark results\n"
    block = f"{heading}\n\n{body.strip()}\n"
    if heading in text:
        start = text.index(heading)
        following = re.search(r"^## ", text[start + len(heading):], flags=re.MULTILINE)
        end = start + len(heading) + following.start() if following else len(text)
        text = text[:start] + block + ("\n" + text[end:] if following else "")
    else:
        text = text.rstrip("\n") + "\n\n" + block
    RESULTS.write_text(text, encoding="utf-8")
