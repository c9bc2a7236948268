"""A socketcand-compatible CAN hub on TCP, so separate processes share one CAN bus.

Clients use python-can's own ``socketcand`` interface (``can.Bus(interface="socketcand", channel="can0",
host=..., port=...)``); the same client talks to a real socketcand gateway in production. Only the rawmode
part of the socketcand protocol is spoken::

    hub: < hi >            client: < open can0 >
    hub: < ok >            client: < rawmode >
    hub: < ok >            client: < send 601 8 40 0 10 0 0 0 0 0 >      (ID, LEN, bytes, all hex)
    hub, to every other client on can0: < frame 601 1732270000.123456 4000100000000000 >

Like a real bus, a frame reaches every other member of its channel, never its sender (python-can's client
does not expect its own frames back). What python-can 4.6.1's client relies on
(``can/interfaces/socketcand/socketcand.py``), and what socketcand itself does (``src/state_raw.c``):

* The handshake replies are compared with one exact ``recv(256)`` each, so every reply is its own write, and
  frames for a new client are held back until it has surely read its rawmode ``< ok >``: until it sends its
  first command or ``settle_s`` has passed, whichever comes first. Held frames are queued, not lost.
* A frame with no data is written ``< frame ID SEC.USEC  >`` (two spaces before ``>``), as socketcand writes it;
  python-can's parser needs the empty third field.
* The extended-ID flag travels as the ID's width: 3 hex digits standard, 8 extended.
* Remote frames cannot travel: python-can's client writes an RTR as ``< send ID LEN >`` without data bytes and
  its parser has no RTR flag; socketcand drops them too. Such a ``send`` is rejected (counted).
* Error frames go out as ``< error CLASS SEC.USEC >`` (socketcand's form, which python-can turns into an error
  frame); only a bridged bus produces them.
* Any other ``< error ... >`` text makes python-can's receive loop raise, so a malformed ``send`` is logged
  and counted, not answered (socketcand does the same); only unknown commands get ``< error ... >``.

A client that reads too slowly loses frames, counted per client like a CAN controller overrun, instead of
stalling everyone else: each client has a queue bounded to ``queue_frames`` (4096 by default) emptied by its
own writer task, on top of what the socket buffers hold.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import can

from drivebench.errors import TransportError
from drivebench.i18n import N_, Text
from drivebench.transport.hub_bridge import BridgeStats, BusBridge

log = logging.getLogger(__name__)

DEFAULT_PORT = 29536
DEFAULT_QUEUE_FRAMES = 4096
DEFAULT_SETTLE_S = 0.5  # a loaded machine may leave a new client unscheduled for a while
MAX_COMMAND_BYTES = 1024  # a classic `send` is < 60 bytes; more without a '>' is garbage
READ_CHUNK_BYTES = 16384  # about 300 `send`s: bounds the burst one sender can queue before any writer runs
MAX_CLASSIC_DLC = 8

HI = b"< hi >"
OK = b"< ok >"
ECHO = b"< echo >"


class CommandError(ValueError):
    """A command from a client that the hub cannot carry out."""


def parse_send(words: list[str]) -> tuple[int, bool, bytes]:
    """``["send", ID, LEN, b0, ...]`` -> (arbitration id, is_extended, data)."""
    if len(words) < 3:
        raise CommandError("send needs ID and LEN")
    id_text, len_text, byte_texts = words[1], words[2], words[3:]
    try:
        can_id = int(id_text, 16)
        length = int(len_text, 16)
        data = bytes(int(text, 16) for text in byte_texts)
    except ValueError as exc:
        raise CommandError(f"send has a field that is not hex: {' '.join(words)}") from exc
    # socketcand marks an extended frame by an 8-digit ID; python-can writes standard IDs with 3 digits.
    is_extended = len(id_text) == 8
    if not is_extended and (len(id_text) > 3 or can_id > 0x7FF):
        raise CommandError(f"send ID {id_text} is neither 3 (standard) nor 8 (extended) hex digits")
    if not 0 <= can_id <= 0x1FFFFFFF:
        raise CommandError(f"send ID {id_text} is not a 29-bit identifier")
    if length > MAX_CLASSIC_DLC or len(data) != length:
        raise CommandError(f"send LEN {len_text} does not match {len(data)} data bytes (classic CAN, 0..8)")
    return can_id, is_extended, data


def format_frame(can_id: int, is_extended: bool, data: bytes, timestamp_ns: int) -> bytes:
    """One ``< frame ... >`` line as socketcand writes it (two spaces before ``>`` when there is no data)."""
    seconds, micros = divmod(timestamp_ns // 1000, 1_000_000)
    id_text = f"{can_id:08X}" if is_extended else f"{can_id:03X}"
    return f"< frame {id_text} {seconds}.{micros:06d} {data.hex().upper()} >".encode("ascii")


def format_error_frame(error_class: int, timestamp_ns: int) -> bytes:
    """An error frame as socketcand writes it: the error class bits (CAN_ERR_*) and the time."""
    seconds, micros = divmod(timestamp_ns // 1000, 1_000_000)
    return f"< error {error_class & 0x1FFFFFFF:03X} {seconds}.{micros:06d} >".encode("ascii")


def error_reply(reason: str) -> bytes:
    cleaned = reason.replace("<", "").replace(">", "")
    return f"< error {cleaned} >".encode("ascii", "replace")


@dataclass(frozen=True)
class ClientStats:
    peer: str
    channel: str | None
    frames_sent: int      # `send` commands relayed from this client
    frames_queued: int    # frames from others accepted into this client's queue
    frames_dropped: int   # frames from others lost because this client read too slowly
    frames_rejected: int  # malformed `send` commands from this client


@dataclass(frozen=True)
class HubStats:
    clients_per_channel: dict[str, int]
    frames_in: int
    frames_relayed: int
    frames_dropped: int
    frames_rejected: int
    clients: tuple[ClientStats, ...]
    bridges: tuple[BridgeStats, ...] = ()


def _handshake_problem(client: _Client, words: list[str]) -> str:
    verb = words[0]
    if verb == "open":
        return "channel already open" if client.channel is not None else "open needs one channel name"
    if verb in ("rawmode", "send"):
        return f"{verb} before open"
    return f"unknown command {verb} (this hub speaks rawmode only)"


class _Client:
    """One TCP connection: its handshake state, outgoing queue and counters."""

    def __init__(self, writer: asyncio.StreamWriter, queue_frames: int) -> None:
        self.writer = writer
        peer = writer.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        self.channel: str | None = None
        self.raw = False
        self.queue_frames = queue_frames
        self.pending: deque[bytes] = deque()
        self.wakeup = asyncio.Event()
        self.released = asyncio.Event()
        self.pump: asyncio.Task[None] | None = None
        self.frames_sent = 0
        self.frames_queued = 0
        self.frames_dropped = 0
        self.frames_rejected = 0

    def offer(self, frame: bytes) -> None:
        if len(self.pending) >= self.queue_frames:
            self.frames_dropped += 1  # overrun: the newest frame is lost, as in a CAN controller
            return
        self.pending.append(frame)
        self.frames_queued += 1
        self.wakeup.set()

    def stats(self) -> ClientStats:
        return ClientStats(self.peer, self.channel, self.frames_sent, self.frames_queued,
                           self.frames_dropped, self.frames_rejected)


class SocketcandHub:
    """Relays every frame a client sends on a channel to every other client that opened that channel."""

    def __init__(self, *, echo_to_sender: bool = False, queue_frames: int = DEFAULT_QUEUE_FRAMES,
                 settle_s: float = DEFAULT_SETTLE_S, send_buffer_bytes: int | None = None,
                 bridges: Sequence[BusBridge] = ()) -> None:
        if queue_frames < 1:
            raise ValueError("queue_frames must be at least 1")
        self.echo_to_sender = echo_to_sender
        self.queue_frames = queue_frames
        self.settle_s = settle_s
        self.send_buffer_bytes = send_buffer_bytes  # SO_SNDBUF per client; None keeps the kernel's autotuning
        self._server: asyncio.Server | None = None
        self._channels: dict[str, dict[_Client, None]] = {}
        self._clients: dict[_Client, None] = {}
        self._handlers: set[asyncio.Task[None]] = set()
        self._bridges = tuple(bridges)
        self._frames_in = 0
        self._retired = ClientStats("", None, 0, 0, 0, 0)  # counters of clients that have left
        self.port = 0

    async def start(self, host: str = "127.0.0.1", port: int = 0) -> int:
        """Listen on host:port (0 picks a free port); returns the bound port."""
        try:
            self._server = await asyncio.start_server(self._handle, host, port)
        except OSError as exc:
            raise TransportError(Text(N_("The CAN hub cannot listen on {host}:{port}: {reason}"), host=host, port=port,
                                       reason=exc.strerror or exc),
                                 hint=N_("Is another hub or program using that port? Pick another with --port."),
                                 ) from exc
        self.port = self._server.sockets[0].getsockname()[1]
        loop = asyncio.get_running_loop()
        try:
            for bridge in self._bridges:
                await asyncio.to_thread(bridge.start, self._bridge_delivery(loop, bridge))
        except BaseException:
            await self.stop()
            raise
        log.info("socketcand hub listening on %s:%d", host, self.port)
        return self.port

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
        for bridge in self._bridges:
            await asyncio.to_thread(bridge.stop)
        for client in list(self._clients):
            client.writer.close()
        if self._handlers:
            await asyncio.wait(list(self._handlers), timeout=2.0)
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    def stats(self) -> HubStats:
        """A snapshot; call it on the hub's loop (``HubHandle.stats()`` does that from other threads)."""
        clients = tuple(client.stats() for client in self._clients)
        everyone = (*clients, self._retired)
        return HubStats(
            clients_per_channel={name: len(members) for name, members in self._channels.items() if members},
            frames_in=self._frames_in,
            frames_relayed=sum(c.frames_queued for c in everyone),
            frames_dropped=sum(c.frames_dropped for c in everyone),
            frames_rejected=sum(c.frames_rejected for c in everyone),
            clients=clients,
            bridges=tuple(bridge.stats() for bridge in self._bridges),
        )

    # --- one connection ----------------------------------------------------------------------------------
    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._handlers.add(task)
        client = _Client(writer, self.queue_frames)
        self._clients[client] = None
        if self.send_buffer_bytes is not None:
            sock = writer.get_extra_info("socket")
            if sock is not None:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.send_buffer_bytes)
        try:
            writer.write(HI)
            await writer.drain()
            buffer = bytearray()
            while True:
                chunk = await reader.read(READ_CHUNK_BYTES)
                if not chunk:
                    break
                buffer += chunk
                await self._take_commands(client, buffer)
        except (ConnectionError, CommandError) as exc:
            log.debug("hub client %s gone: %s", client.peer, exc)
        finally:
            await self._drop(client)
            if task is not None:
                self._handlers.discard(task)

    async def _take_commands(self, client: _Client, buffer: bytearray) -> None:
        while (end := buffer.find(b">")) >= 0:
            start = buffer.rfind(b"<", 0, end)
            text = buffer[start + 1:end].decode("ascii", "replace") if start >= 0 else ""
            del buffer[:end + 1]
            if text.strip():
                await self._command(client, text.split())
        if len(buffer) > MAX_COMMAND_BYTES:
            raise CommandError(f"{len(buffer)} bytes without a closing '>'")

    async def _command(self, client: _Client, words: list[str]) -> None:
        verb = words[0]
        if client.raw:
            client.released.set()  # it sent a command, so it has read its rawmode < ok > by itself
            if verb == "send":
                self._relay(client, words)
            elif verb == "echo":
                client.writer.write(ECHO)
            else:
                client.writer.write(error_reply(f"unknown command {verb} in rawmode"))
            return
        if verb == "echo":
            reply = ECHO
        elif verb == "open" and client.channel is None and len(words) == 2:
            client.channel = words[1]
            reply = OK
        elif verb == "rawmode" and client.channel is not None:
            reply = OK
        else:
            reply = error_reply(_handshake_problem(client, words))
        client.writer.write(reply)
        await client.writer.drain()  # each handshake reply is its own write
        if verb == "rawmode" and reply is OK:
            self._join(client)

    def _join(self, client: _Client) -> None:
        assert client.channel is not None
        client.raw = True
        self._channels.setdefault(client.channel, {})[client] = None
        client.pump = asyncio.create_task(self._pump(client))

    def _relay(self, sender: _Client, words: list[str]) -> None:
        try:
            can_id, is_extended, data = parse_send(words)
        except CommandError as exc:
            sender.frames_rejected += 1
            log.warning("hub client %s: %s", sender.peer, exc)
            return
        frame = format_frame(can_id, is_extended, data, time.time_ns())
        sender.frames_sent += 1
        self._frames_in += 1
        for member in self._channels.get(sender.channel or "", ()):
            if member is not sender or self.echo_to_sender:
                member.offer(frame)
        for bridge in self._bridges:
            if bridge.channel == sender.channel:
                bridge.offer(can.Message(arbitration_id=can_id, is_extended_id=is_extended, data=data))

    def _bridge_delivery(self, loop: asyncio.AbstractEventLoop, bridge: BusBridge) -> Callable[[can.Message], None]:
        def deliver(msg: can.Message) -> None:  # the bridge's reader thread
            loop.call_soon_threadsafe(self._from_bridge, bridge, msg)
        return deliver

    def _from_bridge(self, bridge: BusBridge, msg: can.Message) -> None:
        # Stamped with the hub's clock like every other frame: adapters' own time bases are not all epoch-based.
        now_ns = time.time_ns()
        if msg.is_error_frame:
            frame = format_error_frame(msg.arbitration_id, now_ns)
        else:
            frame = format_frame(msg.arbitration_id, msg.is_extended_id, bytes(msg.data[:MAX_CLASSIC_DLC]), now_ns)
        self._frames_in += 1
        for member in self._channels.get(bridge.channel, ()):
            member.offer(frame)

    async def _pump(self, client: _Client) -> None:
        """Write the client's queue in batches; while it cannot take more, its queue fills and drops."""
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(client.released.wait(), self.settle_s)
        try:
            while True:
                await client.wakeup.wait()
                client.wakeup.clear()
                if not client.pending:
                    continue
                batch = b"".join(client.pending)
                client.pending.clear()
                client.writer.write(batch)
                await client.writer.drain()
        except ConnectionError:
            client.writer.close()

    async def _drop(self, client: _Client) -> None:
        self._clients.pop(client, None)
        if client.channel is not None:
            self._channels.get(client.channel, {}).pop(client, None)
        if client.pump is not None:
            client.pump.cancel()
            with contextlib.suppress(asyncio.CancelledError, ConnectionError):
                await client.pump
        old = self._retired
        self._retired = ClientStats("", None, old.frames_sent + client.frames_sent,
                                    old.frames_queued + client.frames_queued,
                                    old.frames_dropped + client.frames_dropped,
                                    old.frames_rejected + client.frames_rejected)
        client.writer.close()
        with contextlib.suppress(ConnectionError):
            await client.writer.wait_closed()


# --- running it ------------------------------------------------------------------------------------------
class HubHandle:
    """A hub running on its own event loop in a daemon thread."""

    def __init__(self, hub: SocketcandHub, loop: asyncio.AbstractEventLoop, thread: threading.Thread) -> None:
        self.hub = hub
        self.port = hub.port
        self._loop = loop
        self._thread = thread

    def stats(self) -> HubStats:
        async def snapshot() -> HubStats:
            return self.hub.stats()
        return asyncio.run_coroutine_threadsafe(snapshot(), self._loop).result(timeout=5)

    def stop(self) -> None:
        if self._loop.is_closed():
            return
        asyncio.run_coroutine_threadsafe(self.hub.stop(), self._loop).result(timeout=10)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)
        self._loop.close()

    def __enter__(self) -> HubHandle:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()


def start_hub_thread(host: str = "127.0.0.1", port: int = 0, *, echo_to_sender: bool = False,
                     queue_frames: int = DEFAULT_QUEUE_FRAMES, settle_s: float = DEFAULT_SETTLE_S,
                     send_buffer_bytes: int | None = None, bridges: Sequence[BusBridge] = ()) -> HubHandle:
    """Start a hub in a daemon thread; ``.port`` is the bound port, ``.stop()`` closes it and frees the port."""
    hub = SocketcandHub(echo_to_sender=echo_to_sender, queue_frames=queue_frames, settle_s=settle_s,
                        send_buffer_bytes=send_buffer_bytes, bridges=bridges)
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, name=f"socketcand-hub-{port}", daemon=True)
    thread.start()
    try:
        asyncio.run_coroutine_threadsafe(hub.start(host, port), loop).result(timeout=15)
    except BaseException:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout=5)
        loop.close()
        raise
    return HubHandle(hub, loop, thread)


async def serve_hub(host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, echo_to_sender: bool = False,
                    queue_frames: int = DEFAULT_QUEUE_FRAMES, bridges: Sequence[BusBridge] = (),
                    on_listening: Callable[[str, int], None] | None = None) -> None:
    """Run a hub until cancelled (``drivebench hub``); ``on_listening(host, port)`` runs once it is bound."""
    hub = SocketcandHub(echo_to_sender=echo_to_sender, queue_frames=queue_frames, bridges=bridges)
    bound_port = await hub.start(host, port)
    if on_listening is not None:
        on_listening(host, bound_port)
    try:
        await asyncio.Event().wait()
    finally:
        await hub.stop()
