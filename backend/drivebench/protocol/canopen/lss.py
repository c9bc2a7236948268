"""LSS master (CiA 305): layer setting services on a canopen Network, each step answering in words.

canopen 2.4.1's :class:`canopen.lss.LssMaster` sends the unanswered broadcasts here (switch state global, activate
bit timing). What it lacks is written here: every answered request waits for its answer (up to
:attr:`LssMaster.timeout_s`; a fastscan request up to :attr:`LssMaster.window_s`, both settings) and returns on the
first one; a configure step reads the device's error code; several different answers are told apart from one.
canopen's fastscan waits its full 0.5 s timeout on every 1-bit and takes an answer that comes late for none:
:meth:`LssMaster.fastscan` asks the other half of a bit after a miss (every decision is an answer), re-asks once
before it decides, predicts bits from the devices already found, moves the devices on to the next part only by a
part's confirmation, finds and turns back a bit a late answer misled, repeats the whole scan of a device with a
longer window when that is not enough, checks each address found with identify remote slave, and ends after ten
times its slowest answer once the devices found have answered an inquiry sent after the last question. Each found
device is left in LSS configuration state (so the next round finds the next one) until a switch state global
(waiting).

Identical answers of several devices merge into one frame on a real CAN bus: the count of devices that answered
cannot be seen. What is known: *some* device answered; different answers (inquiries in configuration state) mean
more than one device; two devices with the same 128-bit LSS address stay indistinguishable for LSS (a duplicate
node ID after addressing shows them).
"""

from __future__ import annotations

import queue
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import canopen
from canopen import lss as cl

from drivebench.errors import ProtocolError
from drivebench.i18n import N_, Text

LSS_REQUEST_COB = 0x7E5
LSS_ANSWER_COB = 0x7E4
UNCONFIGURED = 0xFF
"""The node ID of a device that has none (CiA 305)."""
FASTSCAN_RESET = 0x80
"""bit_check value that restarts every waiting slave's fastscan (CiA 305)."""
BIT_TIMINGS = {0: 1_000_000, 1: 800_000, 2: 500_000, 3: 250_000, 4: 125_000, 6: 50_000, 7: 20_000, 8: 10_000}
"""CiA 305 bit timing table 0 (index 5 is reserved there; canopen's docstring calls it 100 kbit/s)."""
DEFAULT_WINDOW_S = 0.05
DEFAULT_TIMEOUT_S = 1.0
FASTSCAN_ATTEMPTS = 5
TURN_BACKS = 8
"""How often the scan of one part of an address turns a misled bit back before it scans the device again."""

NO_SLAVE = N_("no LSS slave answered: is a device in LSS waiting state?")


class LssError(ProtocolError):
    title = N_("LSS error")


class LssNoAnswer(LssError):
    title = N_("No LSS answer")


def timing_index(bitrate: int) -> int:
    for index, rate in BIT_TIMINGS.items():
        if rate == bitrate:
            return index
    raise LssError(Text(N_("{rate} bit/s is not in the CiA 305 bit timing table (1000, 800, 500, 250, 125, 50, 20, "
                           "10 kbit/s)."), rate=bitrate))


@dataclass(frozen=True)
class LssAddress:
    """The 128-bit LSS address: identity object 0x1018 sub 1-4."""

    vendor: int
    product: int
    revision: int
    serial: int

    def parts(self) -> tuple[int, int, int, int]:
        return self.vendor, self.product, self.revision, self.serial

    def hex(self) -> dict[str, str]:
        return {"vendor": f"0x{self.vendor:08X}", "product": f"0x{self.product:08X}",
                "revision": f"0x{self.revision:08X}", "serial": f"0x{self.serial:08X}"}


@dataclass
class ScanCount:
    """Frames sent and time spent by one operation."""

    frames: int = 0
    started: float = field(default_factory=time.monotonic)
    retries: int = 0

    @property
    def seconds(self) -> float:
        return time.monotonic() - self.started


@dataclass(frozen=True)
class FastscanResult:
    found: list[LssAddress]
    frames: int
    seconds: float
    retries: int
    window_s: float


class LssMaster:
    """One bus's LSS master. Thread-safe: one exchange at a time. A configuring or inquiring request waits up to
    ``timeout_s`` for its answer (returning at the first); a fastscan request waits at most ``window_s``, narrowed
    to a few times the answer time measured (never below ``min_window_s``)."""

    def __init__(self, network: canopen.Network, *, window_s: float = DEFAULT_WINDOW_S,
                 timeout_s: float = DEFAULT_TIMEOUT_S, min_window_s: float = 0.004) -> None:
        self.network = network
        self.window_s = window_s
        self.timeout_s = timeout_s
        self.min_window_s = min_window_s
        self.last_answer_s = 0.0
        """How long the last answered request waited for its first answer."""
        self._rtt: list[float] = []
        self._floor = min_window_s
        self._answers: queue.Queue[tuple[float, bytes]] = queue.Queue()
        self._lock = threading.Lock()
        self._library = cl.LssMaster()
        self._library.network = network  # the library's master sends the unanswered broadcasts
        network.subscribe(LSS_ANSWER_COB, self._on_answer)

    def close(self) -> None:
        self.network.unsubscribe(LSS_ANSWER_COB, self._on_answer)

    def _on_answer(self, can_id: int, data: bytearray, timestamp: float) -> None:
        self._answers.put((time.monotonic(), bytes(data)))

    # --- the exchange ---------------------------------------------------------------------------------------
    def _drain(self) -> None:
        while True:
            try:
                self._answers.get_nowait()
            except queue.Empty:
                return

    def _send(self, data: bytes, count: ScanCount | None = None) -> None:
        self.network.send_message(LSS_REQUEST_COB, (data + bytes(8))[:8])
        if count is not None:
            count.frames += 1

    def _ask(self, data: bytes, answer_cs: int, window_s: float, count: ScanCount | None = None,
             *, gather_s: float = 0.0) -> list[bytes]:
        """Send ``data`` and return the distinct answers with ``answer_cs``: at once on the first (then
        ``gather_s`` more for different ones), empty after ``window_s`` without."""
        self._drain()
        sent = time.monotonic()
        self._send(data, count)
        deadline = sent + window_s
        answers: list[bytes] = []
        while True:
            left = deadline - time.monotonic()
            try:
                # past the deadline still take what has come (this thread may have been the one held up)
                _at, answer = self._answers.get(timeout=left) if left > 0 else self._answers.get_nowait()
            except queue.Empty:
                return answers
            if answer[:1] != bytes([answer_cs]):
                continue
            if answer not in answers:
                answers.append(answer)
            if len(answers) == 1:
                self.last_answer_s = time.monotonic() - sent
                deadline = time.monotonic() + gather_s

    def _one(self, data: bytes, answer_cs: int, step: str) -> bytes:
        answers = self._ask(data, answer_cs, self.timeout_s, gather_s=0.01)
        if not answers:
            raise LssNoAnswer(Text(N_("no LSS slave answered {step}: is exactly one device in LSS configuration "
                                      "state (switch state selective first)?"), step=step))
        if len(answers) > 1:
            raise LssError(Text(N_("{count} different answers to {step}: more than one device is in LSS "
                                   "configuration state; switch all to waiting and select one."),
                                count=len(answers), step=step))
        return answers[0]

    # --- state switching --------------------------------------------------------------------------------------
    def switch_global(self, configuration: bool) -> None:
        """Every device on the bus to configuration state, or back to waiting (a device given a node ID while it
        had none then starts with it)."""
        with self._lock:
            self._library.send_switch_state_global(cl.LssMaster.CONFIGURATION_STATE if configuration
                                                   else cl.LssMaster.WAITING_STATE)

    def switch_selective(self, address: LssAddress) -> None:
        """The one device with ``address`` to configuration state."""
        with self._lock:
            codes = (cl.CS_SWITCH_STATE_SELECTIVE_VENDOR_ID, cl.CS_SWITCH_STATE_SELECTIVE_PRODUCT_CODE,
                     cl.CS_SWITCH_STATE_SELECTIVE_REVISION_NUMBER)
            for code, value in zip(codes, address.parts()[:3], strict=True):
                self._send(struct.pack("<BI", code, value))
            answers = self._ask(struct.pack("<BI", cl.CS_SWITCH_STATE_SELECTIVE_SERIAL_NUMBER, address.serial),
                                cl.CS_SWITCH_STATE_SELECTIVE_RESPONSE, self.timeout_s)
        if not answers:
            raise LssNoAnswer(Text(N_("no LSS slave with vendor {vendor}, product {product}, revision {revision}, "
                                      "serial {serial} answered: is the device on this bus and in LSS waiting "
                                      "state?"), **address.hex()))

    # --- configuration --------------------------------------------------------------------------------------
    def configure_node_id(self, node_id: int) -> None:
        with self._lock:
            answer = self._one(bytes([cl.CS_CONFIGURE_NODE_ID, node_id]), cl.CS_CONFIGURE_NODE_ID,
                               Text(N_("configure node ID")))
        error, specific = answer[1], answer[2]
        if error == 1:
            raise LssError(Text(N_("the device refused node ID {node}: out of range"), node=node_id))
        if error:
            raise LssError(Text(N_("the device refused node ID {node}: its error {error} ({specific})"),
                                node=node_id, error=error, specific=specific))

    def configure_bit_timing(self, index: int) -> None:
        with self._lock:
            answer = self._one(bytes([cl.CS_CONFIGURE_BIT_TIMING, 0, index]), cl.CS_CONFIGURE_BIT_TIMING,
                               Text(N_("configure bit timing")))
        rate = BIT_TIMINGS.get(index)
        what = f"{rate // 1000} kbit/s" if rate else f"#{index}"
        if answer[1] == 1:
            raise LssError(Text(N_("the device refused bit timing {rate} (table 0, index {index}): not supported"),
                                rate=what, index=index))
        if answer[1]:
            raise LssError(Text(N_("the device refused bit timing {rate}: its error {error} ({specific})"),
                                rate=what, error=answer[1], specific=answer[2]))

    def activate_bit_timing(self, switch_delay_ms: int) -> None:
        """Every device switches to its configured bit timing after ``switch_delay_ms`` and stays silent for a
        second delay (CiA 305); the master must switch its own adapter meanwhile."""
        with self._lock:
            self._library.activate_bit_timing(switch_delay_ms)

    def store_configuration(self) -> None:
        with self._lock:
            answer = self._one(bytes([cl.CS_STORE_CONFIGURATION]), cl.CS_STORE_CONFIGURATION,
                               Text(N_("store configuration")))
        if answer[1] == 1:
            raise LssError(Text(N_("the device cannot store its configuration (not supported)")))
        if answer[1] == 2:
            raise LssError(Text(N_("the device could not store its configuration: storage media access error")))
        if answer[1]:
            raise LssError(Text(N_("the device could not store its configuration: its error {error} ({specific})"),
                                error=answer[1], specific=answer[2]))

    # --- inquiry and identification ---------------------------------------------------------------------------
    def inquire_address(self) -> LssAddress:
        """The identity of the device in configuration state."""
        parts = []
        with self._lock:
            for code in (cl.CS_INQUIRE_VENDOR_ID, cl.CS_INQUIRE_PRODUCT_CODE, cl.CS_INQUIRE_REVISION_NUMBER,
                         cl.CS_INQUIRE_SERIAL_NUMBER):
                answer = self._one(bytes([code]), code, Text(N_("inquire identity")))
                parts.append(struct.unpack_from("<I", answer, 1)[0])
        return LssAddress(*parts)

    def inquire_node_id(self) -> int:
        """The active node ID of the device in configuration state (255: it has none)."""
        with self._lock:
            return self._one(bytes([cl.CS_INQUIRE_NODE_ID]), cl.CS_INQUIRE_NODE_ID,
                             Text(N_("inquire node ID")))[1]

    def identify_remote(self, vendor: int, product: int, revisions: tuple[int, int], serials: tuple[int, int]
                        ) -> bool:
        """Is any device with this vendor and product and revision and serial in the ranges on the bus? (One
        merged answer whatever their number.)"""
        with self._lock:
            return self._identify_remote(vendor, product, revisions, serials, self.timeout_s)

    def _identify_remote(self, vendor: int, product: int, revisions: tuple[int, int], serials: tuple[int, int],
                         wait_s: float, count: ScanCount | None = None) -> bool:
        for code, value in ((cl.CS_IDENTIFY_REMOTE_SLAVE_VENDOR_ID, vendor),
                            (cl.CS_IDENTIFY_REMOTE_SLAVE_PRODUCT_CODE, product),
                            (cl.CS_IDENTIFY_REMOTE_SLAVE_REVISION_NUMBER_LOW, revisions[0]),
                            (cl.CS_IDENTIFY_REMOTE_SLAVE_REVISION_NUMBER_HIGH, revisions[1]),
                            (cl.CS_IDENTIFY_REMOTE_SLAVE_SERIAL_NUMBER_LOW, serials[0])):
            self._send(struct.pack("<BI", code, value), count)
        return bool(self._ask(struct.pack("<BI", cl.CS_IDENTIFY_REMOTE_SLAVE_SERIAL_NUMBER_HIGH, serials[1]),
                              cl.CS_IDENTIFY_SLAVE, wait_s, count))

    def identify_non_configured(self) -> bool:
        """Is any device without a node ID on the bus?"""
        with self._lock:
            return bool(self._ask(bytes([cl.CS_IDENTIFY_NON_CONFIGURED_REMOTE_SLAVE]),
                                  cl.CS_IDENTIFY_NON_CONFIGURED_SLAVE, self.timeout_s))

    # --- fastscan ---------------------------------------------------------------------------------------------
    def fastscan(self, max_devices: int = 127) -> FastscanResult:
        """Every device without a node ID in waiting state, one after the other; each found one is left in
        configuration state (switch all to waiting afterwards: :meth:`switch_global`)."""
        count = ScanCount()
        found: list[LssAddress] = []
        window = self.window_s
        with self._lock:
            self._rtt = []
            self._floor = self.min_window_s
            while len(found) < max_devices:
                address, window = self._find_one(found, count, window)
                if address is None:
                    break
                found.append(address)
        return FastscanResult(found, count.frames, count.seconds, count.retries, window)

    def _window(self, ceiling: float, *, careful: bool = False) -> float:
        """How long a fastscan request waits: three times a typical recent answer time (the upper quartile of the
        last 32), or (``careful``, for asking again after a miss) four times the slowest of them; never below the
        floor nor above ``ceiling``. A miss costs this much; an answer returns at once."""
        if not self._rtt:
            return ceiling
        recent = sorted(self._rtt[-32:])
        typical = 4 * recent[-1] if careful else 3 * recent[(len(recent) * 3) // 4]
        return min(ceiling, max(self._floor, typical))

    def _fs(self, value: int, bit: int, sub: int, nxt: int, count: ScanCount, window: float) -> bool:
        answered = bool(self._ask(struct.pack("<BIBBB", cl.CS_FAST_SCAN, value, bit, sub, nxt),
                                  cl.CS_IDENTIFY_SLAVE, window, count))
        if answered:
            self._rtt.append(self.last_answer_s)
        return answered

    def _find_one(self, found: Sequence[LssAddress], count: ScanCount, ceiling: float
                  ) -> tuple[LssAddress | None, float]:
        self._floor = self.min_window_s  # a longer wait one device needed is not kept for the next
        window = ceiling
        for attempt in range(FASTSCAN_ATTEMPTS):
            if not self._any_left(bool(found), count, window):
                return None, ceiling
            parts = self._scan_parts(found, count, window)
            if parts is not None and self._really(LssAddress(*parts), found, count):
                return LssAddress(*parts), ceiling
            count.retries += 1
            # Answers came late (a busy machine stalls the adapter's or the devices' threads): the whole device
            # again, first with every request waiting at least a quarter of the answer window, then the full window,
            # then four and sixteen times as long (at most timeout_s; an answer returns at once, a miss costs the
            # window). Narrowing pays only while answers come in time; the last attempt is slow, but a slow scan
            # beats a device left out (CI, 2 cores with four workers and a busy thread: 200 ms was not enough).
            window = ceiling if attempt <= 1 else max(ceiling, min(self.timeout_s, 4 ** (attempt - 1) * ceiling))
            self._floor = window / 4 if attempt == 0 else window
        raise LssError(Text(N_("fastscan lost the device it was following ({attempts} attempts, last answer "
                               "window {ms} ms): a device that answers late or leaves waiting state; raise the "
                               "answer window."), attempts=FASTSCAN_ATTEMPTS, ms=round(self._floor * 1000)))

    def _any_left(self, found_here: bool, count: ScanCount, ceiling: float) -> bool:
        """Is any device without node ID left in waiting state? Asked three times; the third time waits longest.
        Before this scan has seen an answer: the full window twice, then ``timeout_s`` (a device held up at the very
        start is not left out: ten windows, 0.5 s, left out a device stalled 0.4 s on a loaded machine; an empty bus
        costs it once); afterwards the careful window twice (mid-scan a device answers at once), then
        :meth:`_last_call`."""
        if not self._rtt:
            return (self._fs(0, FASTSCAN_RESET, 0, 0, count, ceiling)
                    or self._fs(0, FASTSCAN_RESET, 0, 0, count, ceiling)
                    or self._fs(0, FASTSCAN_RESET, 0, 0, count, max(ceiling, self.timeout_s)))
        wait = self._window(ceiling, careful=True)
        return (self._fs(0, FASTSCAN_RESET, 0, 0, count, wait) or self._fs(0, FASTSCAN_RESET, 0, 0, count, wait)
                or self._last_call(found_here, count, ceiling))

    def _last_call(self, found_here: bool, count: ScanCount, ceiling: float) -> bool:
        """The last "is any device left?". It waits ten times this scan's slowest answer, and at least until the
        devices found in this scan (left in configuration state) have answered an inquire node ID sent right after
        it: devices hosted by one busy process (a simulator, a loaded test machine) answer in order, so a device
        held up there answers the question before that inquiry (a fixed ten windows, 500 ms, cost every scan half a
        second and still left a device stalled longer out). At most ``timeout_s`` (a device that does not answer
        the inquiry costs that); without a device found in this scan ten answer windows (at most ``timeout_s``)."""
        cap = self.timeout_s if found_here else min(self.timeout_s, 10 * ceiling)
        short = min(cap, max(self._floor, 10 * max(self._rtt)))
        self._drain()
        sent = time.monotonic()
        self._send(struct.pack("<BIBBB", cl.CS_FAST_SCAN, 0, FASTSCAN_RESET, 0, 0), count)
        fenced = False
        if found_here:
            self._send(bytes([cl.CS_INQUIRE_NODE_ID]), count)
        while True:
            left = sent + (short if fenced else cap) - time.monotonic()
            try:
                _at, answer = self._answers.get(timeout=left) if left > 0 else self._answers.get_nowait()
            except queue.Empty:
                return False
            if answer[:1] == bytes([cl.CS_IDENTIFY_SLAVE]):
                self._rtt.append(time.monotonic() - sent)
                return True
            fenced = fenced or answer[:1] == bytes([cl.CS_INQUIRE_NODE_ID])

    def _really(self, address: LssAddress, found: Sequence[LssAddress], count: ScanCount) -> bool:
        """The address is a device's (identify remote slave: an answer late from an earlier request may have been
        taken for the last confirmation's) and not one found before."""
        vendor, product, revision, serial = address.parts()
        return address not in found and self._identify_remote(vendor, product, (revision, revision),
                                                               (serial, serial), self.timeout_s, count)

    def _scan_parts(self, found: Sequence[LssAddress], count: ScanCount, ceiling: float) -> list[int] | None:
        parts: list[int] = []
        for sub in range(4):
            nxt = (sub + 1) & 3
            likely, hints = _hints(found, parts)
            # A value is asked whole without moving the devices on (lss_next = lss_sub): an answer that came late
            # would otherwise leave a device a part ahead unseen, and the next part scanned from another device.
            value = next((hint for hint in likely if self._fs(hint, 0, sub, sub, count, self._window(ceiling))),
                         None)
            if value is None:
                value = self._scan_bits(sub, hints, count, ceiling)
                if value is None:
                    return None
            # Only the confirmation moves them on: every device a part further has the parts found so far.
            if not self._fs(value, 0, sub, nxt, count, ceiling) and sub < 3:
                return None  # (the last part's confirmation, answered late, has put the device in configuration
                # state: identify remote slave, :meth:`_really`, tells)
            parts.append(value)
        return parts

    def _scan_bits(self, sub: int, hints: list[int], count: ScanCount, ceiling: float) -> int | None:
        """The 32 bits of ``sub``, highest first. Every bit is decided by an answer: the predicted half is asked,
        on a miss the other half. An answer that came late is taken for the next request's: then no half of a lower
        bit answers. That bit is found and turned back (a bit decided after a short wait first; else the prefix is
        asked at ever higher bits: the first answered lies just above the misled bit), at most
        :data:`TURN_BACKS` times a part before the whole device is scanned again with longer windows."""
        value, bit, doubtful, turned, top_turned = 0, 31, set[int](), 0, False
        while True:
            if bit < 0:  # all 32 decided; one decided after a short wait is checked whole (not moving it on)
                if not doubtful or self._fs(value, 0, sub, sub, count, self._window(ceiling, careful=True)):
                    return value
            else:
                decided = self._decide(value, bit, sub, hints, count, ceiling)
                if decided is not None:
                    value, shaky = decided
                    if shaky:
                        doubtful.add(bit)
                    bit -= 1
                    continue
            turned += 1
            count.retries += 1
            if turned > TURN_BACKS:
                return None
            upper = min((b for b in doubtful if b > bit), default=None)
            if upper is not None:
                doubtful = {b for b in doubtful if b < upper}
                back = (value ^ (1 << upper)) & ~((1 << upper) - 1)
                if self._fs(back, upper, sub, sub, count, ceiling):
                    value, bit = back, upper - 1
                    continue
            level = self._answered_level(value, bit + 1, sub, count, ceiling)
            if level == 32:
                if top_turned:
                    return None  # not this part's bits: an earlier part's, or the device left
                top_turned = True
            doubtful = {b for b in doubtful if b < level}
            if level > bit + 1:  # the prefix one bit lower was not answered: that bit was misled
                value = (value ^ (1 << (level - 1))) & ~((1 << (level - 1)) - 1)
                bit = level - 2
            # else the prefix is right and both halves of the bit answered late twice: asked again

    def _decide(self, value: int, bit: int, sub: int, hints: list[int], count: ScanCount, ceiling: float
                ) -> tuple[int, bool] | None:
        """``value`` with ``bit`` decided by an answer, and whether that came after a short wait for the other half
        (an answer late from it may have been taken); None when no half answered, even after a longer wait."""
        high = ~((1 << (bit + 1)) - 1) & 0xFFFFFFFF
        like = next((hint for hint in hints if (hint ^ value) & high == 0), 0)
        first = value | (like & (1 << bit))
        second = first ^ (1 << bit)
        fast, careful = self._window(ceiling), self._window(ceiling, careful=True)
        for window in (fast, careful):  # a miss is asked again once, waiting longer
            if self._fs(first, bit, sub, sub, count, window):
                return first, False
            if self._fs(second, bit, sub, sub, count, window):
                return second, window < careful
        return None

    def _answered_level(self, value: int, lowest: int, sub: int, count: ScanCount, ceiling: float) -> int:
        """The lowest bit check from ``lowest`` up whose prefix of ``value`` a device answers; 32 when not even bit
        31's (only bit 31 is then left to be wrong). The two lowest are asked first (a late answer misleads the next
        bit or two), then halves: a device that matches a prefix matches every shorter one."""
        careful = self._window(ceiling, careful=True)
        for level in range(lowest, min(lowest + 2, 32)):
            if self._fs(value, level, sub, sub, count, careful):
                return level
        low, high = min(lowest + 2, 32), 32  # the prefix at ``high`` is answered (32: the empty prefix)
        while low < high:
            middle = (low + high) // 2
            if self._fs(value, middle, sub, sub, count, careful):
                high = middle
            else:
                low = middle + 1
        return high

def _hints(found: Sequence[LssAddress], parts: list[int]) -> tuple[list[int], list[int]]:
    """The values the next part of the address may well have: (worth asking whole, to prefer bit by bit). Asked
    whole: those of the devices found whose parts so far are the same (most frequent first), never their serial
    number (two devices with the same vendor, product and revision differ there); a miss costs an answer window.
    Preferred bit by bit: those, then the other devices' values."""
    sub = len(parts)
    kin = [address.parts()[sub] for address in found if list(address.parts()[:sub]) == parts]
    likely = sorted(dict.fromkeys(kin), key=kin.count, reverse=True) if sub < 3 else []
    return likely, list(dict.fromkeys([*kin, *(address.parts()[sub] for address in found)]))
