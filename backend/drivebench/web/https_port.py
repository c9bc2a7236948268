"""The https port answers plain http in words (issue 33): uvicorn's server, its listening sockets accepted here.

uvicorn wraps every accepted connection in TLS at once, so a browser or curl speaking ``http://`` to the https port
got an empty reply. Here each connection's first byte is looked at without taking it (``MSG_PEEK``) before any TLS:
a TLS record that starts a handshake (the ClientHello) begins with 0x16, and such a connection goes on to uvicorn's
HTTP protocol through asyncio's TLS with uvicorn's own context, as uvicorn's server would have handed it. Anything
else gets ``400`` with a line in words naming the https address to open, and is closed.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import logging
import re
import socket
import ssl
import sys
from collections.abc import Callable

import uvicorn
from starlette.datastructures import Headers
from uvicorn.config import STARTUP_FAILURE

from drivebench import i18n
from drivebench.i18n import _
from drivebench.web import language
from drivebench.web.serving import HEADER_TIMEOUT_S, MAX_HEADER_BYTES, max_connections

TLS_HANDSHAKE = b"\x16"
"""The content type of a TLS record that carries a handshake message: the first byte a TLS client sends."""

DRAIN_S = 2.0
"""How long a plain-http client may go on sending after its answer before the connection is closed anyway."""

logger = logging.getLogger("uvicorn.error")
_HOST = re.compile(r"(?P<host>[A-Za-z0-9.-]+|\[[0-9A-Fa-f:.]+\])(?::(?P<port>\d{1,5}))?")


class HttpsPortServer(uvicorn.Server):
    """uvicorn's server for https (``config.ssl``) whose port answers plain http with a 400 in words."""

    _sorters: list[_Sorter]

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=[])  # the lifespan and uvicorn's state; no listener of its own
        try:
            listeners = sockets or listening(self.config.host, self.config.port, self.config.backlog)
        except OSError as exc:
            logger.error(exc)
            await self.lifespan.shutdown()
            sys.exit(STARTUP_FAILURE)
        most = max_connections()
        self._sorters = [_Sorter(sock, self._protocol, self.config.ssl, most) for sock in listeners]
        for sock in listeners:
            host, port = sock.getsockname()[:2]
            logger.info("Uvicorn running on https://%s:%d (Press CTRL+C to quit)",
                        f"[{host}]" if ":" in host else host, port)

    def _protocol(self) -> asyncio.Protocol:
        """What uvicorn's own server makes for each connection."""
        return self.config.http_protocol_class(  # type: ignore[call-arg]
            config=self.config, server_state=self.server_state, app_state=self.lifespan.state)

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        for sorter in getattr(self, "_sorters", []):
            sorter.close()
        await super().shutdown(sockets=sockets)


def listening(host: str | None, port: int, backlog: int) -> list[socket.socket]:
    """Non-blocking listening sockets on each address of ``host`` (as asyncio's ``create_server`` binds them)."""
    found = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    sockets: list[socket.socket] = []
    try:
        for family, kind, proto, _name, address in dict.fromkeys(found):
            sock = socket.socket(family, kind, proto)
            sockets.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            sock.bind(address)
            sock.listen(backlog)
            sock.setblocking(False)
    except OSError:
        for sock in sockets:
            sock.close()
        raise
    return sockets


class _Sorter:
    """Accepts on one listening socket; hands TLS to ``protocol`` under ``tls``, answers anything else in words.
    At most ``most`` connections wait to be sorted (a client that sends nothing is closed after the header
    deadline), so a flood of silent connections cannot use up the open files."""

    def __init__(self, listener: socket.socket, protocol: Callable[[], asyncio.Protocol], tls: ssl.SSLContext | None,
                 most: int) -> None:
        self.listener, self.protocol, self.tls, self.most = listener, protocol, tls, most
        self.sorting: set[asyncio.Task[None]] = set()
        self.accepting = asyncio.get_running_loop().create_task(self._accept())

    def close(self) -> None:
        self.accepting.cancel()
        for task in list(self.sorting):
            task.cancel()
        self.listener.close()

    async def _accept(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            try:
                connection, _peer = await loop.sock_accept(self.listener)
            except OSError as exc:  # out of open files, mostly: the connections that hold them end, then go on
                logger.error("accepting a connection: %s", exc)
                await asyncio.sleep(0.5)
                continue
            if len(self.sorting) >= self.most:
                connection.close()
                continue
            task = loop.create_task(self._sort(connection))
            self.sorting.add(task)
            task.add_done_callback(self.sorting.discard)

    async def _sort(self, connection: socket.socket) -> None:
        connection.setblocking(False)
        handed = False
        try:
            first = await _peek(connection)
            if first == TLS_HANDSHAKE and self.tls is not None:
                await asyncio.get_running_loop().connect_accepted_socket(
                    self.protocol, connection, ssl=self.tls)
                handed = True  # the transport holds the connection now
            elif first:
                await _answer_plain_http(connection)
        except (OSError, TimeoutError, ssl.SSLError) as exc:  # a failed handshake: as uvicorn's server, not logged
            logger.debug("connection not served: %r", exc)
        finally:
            if not handed:
                connection.close()


async def _peek(connection: socket.socket) -> bytes:
    """The connection's first byte, left unread; ``b""`` when the client closed without sending."""
    loop = asyncio.get_running_loop()
    readable: asyncio.Future[None] = loop.create_future()

    def ready() -> None:
        if not readable.done():
            readable.set_result(None)

    loop.add_reader(connection.fileno(), ready)
    try:
        await asyncio.wait_for(readable, HEADER_TIMEOUT_S)
    finally:
        loop.remove_reader(connection.fileno())
    return connection.recv(1, socket.MSG_PEEK)


async def _answer_plain_http(connection: socket.socket) -> None:
    loop = asyncio.get_running_loop()
    head = b""
    async with asyncio.timeout(HEADER_TIMEOUT_S):
        while b"\r\n\r\n" not in head and len(head) < MAX_HEADER_BYTES:
            chunk = await loop.sock_recv(connection, 4096)
            if not chunk:
                break
            head += chunk
    await loop.sock_sendall(connection, plain_http_answer(head, connection.getsockname()))
    connection.shutdown(socket.SHUT_WR)
    with contextlib.suppress(TimeoutError, OSError):  # read what it still sends, so closing resets nothing unread
        async with asyncio.timeout(DRAIN_S):
            while await loop.sock_recv(connection, 4096):
                pass


def plain_http_answer(head: bytes, server_address: tuple[str, int] | tuple[str, int, int, int]) -> bytes:
    """``400`` in the client's language (its Accept-Language and language cookie), naming the https address: the
    host of the request's Host header (its port, else 80: the port the client reached), else the server's own."""
    headers = _headers(head)
    url = _https_url(headers.get("host"), server_address)
    locale = language.of_request(headers)
    with i18n.using(locale):
        text = html.escape(_("This port speaks HTTPS: open {url}")).format(
            url=f'<a href="{html.escape(url)}">{html.escape(url)}</a>')
        title = html.escape(_("HTTPS only"))
    body = (f'<!doctype html>\n<html lang="{locale}"><head><meta charset="utf-8"><title>{title}</title></head>\n'
            f"<body><p>{text}</p></body></html>\n").encode()
    return (b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/html; charset=utf-8\r\n"
            + f"Content-Length: {len(body)}\r\nContent-Language: {locale}\r\n".encode()
            + b"Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n" + body)


def _headers(head: bytes) -> Headers:
    raw: list[tuple[bytes, bytes]] = []
    for line in head.split(b"\r\n\r\n", 1)[0].split(b"\r\n")[1:]:
        name, colon, value = line.partition(b":")
        if colon and name.strip():
            raw.append((name.strip().lower(), value.strip()))
    return Headers(raw=raw)


def _https_url(host_header: str | None, server_address: tuple[str, int] | tuple[str, int, int, int]) -> str:
    given = _HOST.fullmatch(host_header.strip()) if host_header else None
    if given is not None and int(given["port"] or 80) <= 65535:
        return f"https://{given['host']}:{given['port'] or 80}/"
    host, port = server_address[:2]
    return f"https://{f'[{host}]' if ':' in host else host}:{port}/"
