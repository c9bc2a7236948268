"""The monitor against a known frame list on a real virtual bus: counts per service, node and COB-ID, bits and
load, the decoded trace, and recordings read back by python-can's readers (and tshark for pcapng)."""

from __future__ import annotations

import asyncio
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.protocol.canopen.nmt import NmtCommand
from drivebench.services.bus.sessions import Session
from drivebench.services.monitoring.monitor import Monitor, MonitorFilter, MonitorView, monitor_for
from drivebench.services.monitoring.recording import Recordings
from drivebench.services.session_manager import SessionManager
from drivebench.transport.busload import reference_bits
from drivebench.transport.pcapng import read_pcapng
from tests.conftest import wait_until


def _frame(cob_id: int, data: bytes = b"", **kwargs: object) -> can.Message:
    return can.Message(arbitration_id=cob_id, data=data, is_extended_id=bool(kwargs.pop("extended", False)),
                       **kwargs)  # type: ignore[arg-type]


# What the "devices" (the wire bus) send. The session itself sends one NMT command (observed on transmit).
WIRE_FRAMES = [
    _frame(0x080), _frame(0x080), _frame(0x080),                                   # SYNC x3
    _frame(0x705, bytes([0x05])), _frame(0x705, bytes([0x05])),                     # heartbeat node 5 x2
    _frame(0x70C, bytes([0x00])),                                                   # boot-up node 12
    _frame(0x085, bytes.fromhex("1032110000000000")),                               # EMCY node 5
    *[_frame(0x185, bytes([i, 0, 0x27, 0x06])) for i in range(4)],                  # TPDO1 node 5 x4
    _frame(0x205, bytes([0x0F, 0x00])), _frame(0x205, bytes([0x0F, 0x00])),         # RPDO1 node 5 x2
    _frame(0x605, bytes.fromhex("40C25F0000000000")),                               # SDO request node 5
    _frame(0x585, bytes.fromhex("4BC25F002B000000")),                               # SDO response node 5
    _frame(0x100, bytes.fromhex("0000000012340000")),                               # TIME
    _frame(0x7E5, bytes.fromhex("5E00000000000000")),                               # LSS
    _frame(0x18FF0001, bytes([1, 2, 3]), extended=True),                            # unknown (29 bit)
    _frame(0x004, bytes([0xAA])),                                                   # unknown (11 bit)
    can.Message(arbitration_id=0x080, is_error_frame=True, data=bytes(8)),          # error frame
]
NMT_START_ALL = _frame(0x000, bytes([0x01, 0x00]))


@pytest.fixture
def session(channel: str, registry: ProfileRegistry) -> Iterator[Session]:
    manager = SessionManager(registry)
    opened = asyncio.run(manager.open(f"virtual:{channel}@500000", "Line 1"))
    opened.add_node(5, "lenze-8400-motec-canopen")
    opened.add_node(12, "lenze-8200-vector-emf2178ib")
    yield opened
    opened.close()


def _feed(session: Session, wire: can.BusABC) -> Monitor:
    monitor = monitor_for(session)
    session.network.send_nmt(NmtCommand.START, 0)
    for msg in WIRE_FRAMES:
        wire.send(msg)
    assert wait_until(lambda: monitor.snapshot()["totals"]["frames"] + monitor.snapshot()["totals"]["errors"]
             == len(WIRE_FRAMES) + 1)
    return monitor


def test_counts_per_service_node_and_cob_id(session: Session, wire: can.BusABC) -> None:
    monitor = _feed(session, wire)
    snap = monitor.snapshot()
    services = {row["service"]: row["total"] for row in snap["services"]}
    assert services == {"NMT": 1, "SYNC": 3, "EMCY": 1, "TIME": 1, "TPDO1": 4, "TPDO2": 0, "TPDO3": 0, "TPDO4": 0,
                        "TPDO5+": 0, "RPDO1": 2, "RPDO2": 0, "RPDO3": 0, "RPDO4": 0, "RPDO5+": 0, "SDO rx": 1,
                        "SDO tx": 1, "Heartbeat": 3, "LSS": 1, "Unknown": 2}
    nodes = {row["node"]: row["total"] for row in snap["nodes"]}
    assert nodes == {5: 2 + 1 + 4 + 2 + 1 + 1, 12: 1}
    cobs = {row["text"]: row["total"] for row in snap["cob_ids"]}
    assert cobs["0x185"] == 4 and cobs["0x080"] == 3 and cobs["0x18FF0001"] == 1 and cobs["0x000"] == 1
    assert snap["totals"]["errors"] == 1
    assert snap["totals"]["frames"] == len(WIRE_FRAMES)  # 18 data frames + the NMT, minus the error frame
    expected_bits = sum(reference_bits(m.arbitration_id, m.is_extended_id, m.is_remote_frame, m.dlc, bytes(m.data))
                        for m in [NMT_START_ALL, *WIRE_FRAMES] if not m.is_error_frame)
    assert snap["totals"]["bits"] == expected_bits
    shares = sum(row["share_percent"] for row in snap["cob_ids"])
    assert shares == pytest.approx(100.0, abs=0.1)
    # Load: every bit lands in a one-second bucket of the history once the second is over.
    # At 500 kbit/s one bit is 0.0002 % of a second; points are rounded to 0.001 % (5 bits).
    def history_bits() -> float:
        return sum(load for _, load in monitor.history()) * 5000

    assert wait_until(lambda: history_bits() == pytest.approx(expected_bits, abs=5 * len(monitor.history())), 10.0)
    assert snap["load"]["peak_percent"] >= 0


def test_rates_decay_when_a_cob_id_goes_silent(session: Session, wire: can.BusABC) -> None:
    monitor = _feed(session, wire)

    def rate_185() -> float:
        rates: dict[str, float] = {row["text"]: row["rate"] for row in monitor.snapshot()["cob_ids"]}
        return rates["0x185"]

    assert wait_until(lambda: rate_185() > 0, 10.0)  # rates come from closed windows (here: 5 s after their end)
    assert wait_until(lambda: rate_185() == 0, 15.0)
    assert monitor.snapshot()["cob_ids"][0]["total"] >= 1  # totals stay


def test_trace_rows_are_decoded_with_profile_names(session: Session, wire: can.BusABC) -> None:
    monitor = _feed(session, wire)
    texts = [row["text"] for row in monitor.trace_rows(limit=100)]
    assert "0x000 NMT: Start remote node: all nodes" in texts
    assert "0x605 SDO rx node 5: read 0x5FC2sub0 (C00061 Heatsink temperature)" in texts
    assert "0x705 Heartbeat node 5: Operational" in texts
    assert "0x70C Heartbeat node 12: Boot-up" in texts
    assert any(t.startswith("0x085 EMCY node 5: 0x3210") for t in texts)
    assert any("Error frame" in t and "lost arbitration" not in t for t in texts)
    monitor.set_filter(MonitorFilter(services={"SDO"}))
    assert [row["cob_id"] for row in monitor.trace_rows()] == ["0x605", "0x585"]
    monitor.set_filter(MonitorFilter(nodes={12}))
    assert [row["cob_id"] for row in monitor.trace_rows()] == ["0x70C"]
    monitor.set_filter(MonitorFilter(cob_min=0x180, cob_max=0x1FF))
    assert {row["cob_id"] for row in monitor.trace_rows()} == {"0x185"}
    assert len(monitor.trace_rows(limit=2)) == 2


def test_pause_freezes_the_view_reset_clears(session: Session, wire: can.BusABC) -> None:
    monitor = _feed(session, wire)
    monitor.pause()
    rows_before = monitor.trace_rows()
    wire.send(_frame(0x185, bytes(4)))
    assert wait_until(lambda: monitor.counts_for([0x185]) == 5)  # counting goes on underneath
    assert monitor.snapshot()["totals"]["frames"] == len(WIRE_FRAMES)  # the view is frozen
    assert monitor.snapshot()["paused"] is True
    assert monitor.trace_rows() == rows_before
    monitor.resume()
    assert monitor.snapshot()["totals"]["frames"] == len(WIRE_FRAMES) + 1
    monitor.reset()
    snap = monitor.snapshot()
    assert snap["totals"]["frames"] == 0 and snap["cob_ids"] == [] and monitor.trace_rows() == []


def test_views_filter_and_pause_on_their_own(session: Session, wire: can.BusABC) -> None:
    """Two viewers of one monitor: each sees its own filter; one's pause freezes only its view; the REST view
    (``defaults``) is a third, untouched."""
    monitor = _feed(session, wire)
    sdo, node_12 = MonitorView(MonitorFilter(services={"SDO"})), MonitorView(MonitorFilter(nodes={12}))
    assert [row["cob_id"] for row in monitor.trace_rows(view=sdo)] == ["0x605", "0x585"]
    assert [row["cob_id"] for row in monitor.trace_rows(view=node_12)] == ["0x70C"]
    assert [row["text"] for row in monitor.snapshot(node_12)["cob_ids"]] == ["0x70C"]
    assert [row["node"] for row in monitor.snapshot(node_12)["nodes"]] == [12]
    assert len(monitor.snapshot()["cob_ids"]) == len(monitor.live_snapshot()["cob_ids"]) > 2
    monitor.pause(sdo)
    wire.send(_frame(0x605, bytes.fromhex("40C25F0000000000")))
    wire.send(_frame(0x70C, bytes([0x7F])))
    assert wait_until(lambda: monitor.counts_for([0x605, 0x70C]) == 4)
    assert [row["cob_id"] for row in monitor.trace_rows(view=sdo)] == ["0x605", "0x585"]  # frozen
    assert monitor.snapshot(sdo)["paused"] is True
    assert monitor.snapshot(sdo)["totals"]["frames"] == len(WIRE_FRAMES)
    assert [row["cob_id"] for row in monitor.trace_rows(view=node_12)] == ["0x70C", "0x70C"]  # live
    assert monitor.snapshot(node_12)["totals"]["frames"] == len(WIRE_FRAMES) + 2
    assert monitor.paused is False and monitor.snapshot()["paused"] is False
    monitor.resume(sdo)
    assert [row["cob_id"] for row in monitor.trace_rows(view=sdo)] == ["0x605", "0x585", "0x605"]


def test_bus_state_from_error_frames(session: Session, wire: can.BusABC) -> None:
    """SocketCAN error frames (linux/can/error.h): controller status in data[1], TEC/REC in data[6]/data[7]."""
    monitor = monitor_for(session)

    def error_frame(error_class: int, status: int = 0, tec: int = 0, rec: int = 0) -> can.Message:
        return can.Message(arbitration_id=error_class, is_error_frame=True,
                           data=bytes([0, status, 0, 0, 0, 0, tec, rec]))

    def bus() -> dict[str, object]:
        return monitor.snapshot()["bus"]  # type: ignore[no-any-return]

    assert bus() == {"state": "active", "adapter_state": "active", "tx_errors": None, "rx_errors": None,
                     "reported_age_s": None}
    steps = [(error_frame(0x004, 0x08, 97, 3), ("warning", 97, 3)),     # CRTL: TX warning
             (error_frame(0x004, 0x20, 128, 3), ("passive", 128, 3)),   # CRTL: TX passive
             (error_frame(0x040), ("bus-off", None, None)),             # BUSOFF (no counters: TEC > 255)
             (error_frame(0x100), ("active", None, None)),              # RESTARTED
             (error_frame(0x200, 0, 10, 120), ("warning", 10, 120)),    # CNT only: REC 120 >= 96
             (error_frame(0x004, 0x40, 0, 0), ("active", 0, 0))]        # CRTL: back to error active
    for frame, (state, tec, rec) in steps:
        wire.send(frame)
        assert wait_until(lambda state=state, tec=tec, rec=rec: (bus()["state"], bus()["tx_errors"], bus()["rx_errors"])
                 == (state, tec, rec))
    assert monitor.snapshot()["totals"]["errors"] == len(steps)


def test_trace_ring_is_bounded(session: Session) -> None:
    monitor = Monitor(session, trace_capacity=50, history_s=5)
    for i in range(500):
        monitor.on_message_received(_frame(0x181 + (i % 3), bytes([i % 256])))
    assert monitor.buffer_sizes()["trace"] == 50
    rows = monitor.trace_rows(limit=1000)
    assert len(rows) == 50 and rows[-1]["seq"] == 500
    assert monitor.trace_rows(after=495) == rows[-5:]


@pytest.mark.parametrize("fmt", ["log", "asc", "blf", "trc", "csv", "pcapng"])
def test_recording_reads_back(session: Session, wire: can.BusABC, tmp_path: Path, fmt: str) -> None:
    recordings = Recordings(session, tmp_path)
    recorder = recordings.start(fmt)
    for msg in WIRE_FRAMES:
        wire.send(msg)
    assert wait_until(lambda: recorder.frames == len(WIRE_FRAMES))
    recordings.stop()
    [info] = recordings.list()
    assert info.format == fmt and info.size > 0 and not info.active
    path = recordings.path(info.name)
    reader = {"log": can.LogReader, "asc": can.ASCReader, "blf": can.BLFReader, "trc": can.TRCReader,
              "csv": can.CSVReader}.get(fmt)
    read = list(reader(path)) if reader else list(read_pcapng(path))  # type: ignore[operator]
    written_frames = WIRE_FRAMES
    if fmt == "trc":
        # python-can's TRC writer (file version 2.1) writes no error frames: it skips them.
        written_frames = [msg for msg in WIRE_FRAMES if not msg.is_error_frame]
    assert len(read) == len(written_frames)
    for written, back in zip(written_frames, read, strict=True):
        assert back.is_error_frame == written.is_error_frame, fmt
        if written.is_error_frame:
            continue  # the candump/ASC formats keep only that it was an error frame, not its class
        assert back.arbitration_id == written.arbitration_id, fmt
        assert back.is_extended_id == written.is_extended_id, fmt
        assert bytes(back.data) == bytes(written.data), fmt


def test_pcapng_decodes_as_canopen_in_tshark(session: Session, wire: can.BusABC, tmp_path: Path) -> None:
    tshark = shutil.which("tshark")
    if tshark is None:
        pytest.skip("tshark is not installed")
    recordings = Recordings(session, tmp_path)
    recorder = recordings.start("pcapng")
    for msg in WIRE_FRAMES:
        wire.send(msg)
    assert wait_until(lambda: recorder.frames == len(WIRE_FRAMES))
    recordings.stop()
    path = recordings.path(recordings.list()[0].name)
    result = subprocess.run([tshark, "-r", str(path), "-d", "can.subdissector,canopen", "-T", "fields",
                             "-e", "can.id", "-e", "canopen.sdo.main_idx", "-e", "_ws.col.Info"],
                            capture_output=True, text=True, timeout=60, check=True)
    lines = [line.split("\t") for line in result.stdout.rstrip("\n").split("\n")]
    assert len(lines) == len(WIRE_FRAMES)
    assert lines[0][2] == "SYNC"
    assert lines[3][2].startswith("NMT Error Control: Operational")
    assert lines[13] == ["1541", "0x5fc2", "Default-SDO (rx): Initiate upload request"]
    assert lines[17][0] == str(0x18FF0001)
    assert "ERR" in lines[19][2]
