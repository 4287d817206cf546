"""A WebSocket relayed to a server on loopback: how the dashboard's app serves the Foxglove SDK's
server (:mod:`dashboard.foxglove_live`) on its own port, behind its own token.

For each client of the app's route, the relay first connects to the loopback server itself,
offering the subprotocols the client offered (the Foxglove WebSocket protocol's), and accepts
the client with the one the server chose; then it passes every message on, text and binary,
each way, until either side closes, and closes the other with the same code. A server that
refuses the connection (no subprotocol it speaks) refuses the client: it is closed before it is
accepted (HTTP 403).

Memory stays bounded: a message waits for its receiver before the next one is read, so a slow
client backs up the loopback connection, and the SDK drops its oldest queued messages for that
client.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from fastapi import WebSocket, WebSocketDisconnect
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake

OPEN_S = 5.0
"""The longest the loopback server may take to accept the relay's connection."""
MAX_MESSAGE = 64 * 2**20
"""The largest message taken from the loopback server (bytes)."""
LOG = logging.getLogger("heft.dashboard")
_GONE = (WebSocketDisconnect, ConnectionClosed, RuntimeError, OSError)
"""What sending to a side that went away raises."""


async def relay(websocket: WebSocket, upstream: str) -> None:
    """Relay ``websocket`` (not accepted yet) to the server at ``upstream`` until either
    closes."""
    offered = websocket.scope.get("subprotocols") or None
    try:
        server = await connect(
            upstream,
            subprotocols=offered,
            compression=None,
            proxy=None,
            open_timeout=OPEN_S,
            ping_interval=None,
            max_size=MAX_MESSAGE,
        )
    except (InvalidHandshake, OSError, TimeoutError) as err:
        LOG.info("dashboard: a relayed WebSocket was refused by %s: %s", upstream, err)
        await websocket.close(code=1008, reason=f"refused: {err}"[:120])
        return
    try:
        await websocket.accept(subprotocol=server.subprotocol)
        tasks = {
            asyncio.create_task(_to_server(websocket, server)),
            asyncio.create_task(_to_client(server, websocket)),
        }
        _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in pending:
            task.cancel()
        await asyncio.gather(*pending, return_exceptions=True)
        if server.close_code is not None:  # the server ended it: so does the client
            with contextlib.suppress(*_GONE):
                await websocket.close(_sendable(server.close_code), server.close_reason or "")
    finally:
        # The server's close frame may wait behind messages no one reads any more: read on.
        drain = asyncio.create_task(_discard(server))
        await server.close()
        drain.cancel()
        await asyncio.gather(drain, return_exceptions=True)


async def _discard(server: ClientConnection) -> None:
    with contextlib.suppress(ConnectionClosed):
        async for _ in server:
            pass


def _sendable(code: int) -> int:
    """``code`` if a close frame may carry it, else 1011 (the server went wrong): 1005, 1006
    and 1015 only say that a connection ended without one."""
    return code if 1000 <= code < 5000 and code not in (1004, 1005, 1006, 1015) else 1011


async def _to_server(websocket: WebSocket, server: ClientConnection) -> None:
    """The client's messages, to the server, until the client goes."""
    with contextlib.suppress(*_GONE):
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            text = message.get("text")
            await server.send(text if text is not None else message.get("bytes") or b"")


async def _to_client(server: ClientConnection, websocket: WebSocket) -> None:
    """The server's messages, to the client, until the server goes."""
    with contextlib.suppress(*_GONE):
        async for message in server:
            if isinstance(message, str):
                await websocket.send_text(message)
            else:
                await websocket.send_bytes(message)
