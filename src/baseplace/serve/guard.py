"""What a request must show before the service reads it (issue 28): the HTTP-level limits.

:class:`Guard` is the outermost ASGI middleware. In order, before any body is read:

1. ``Host`` names this service (127.0.0.1, localhost, [::1], ``--host``, ``--allow-host``), else
   400: a page on another site that re-points its own name at this machine (DNS rebinding) is
   refused;
2. an ``Origin`` header names this service's own origin or an ``--allow-origin``, else 403: a
   web page the operator visits cannot drive the service;
3. with a token (``--token``, ``$BASEPLACE_TOKEN``), ``Authorization: Bearer TOKEN``, compared in
   constant time, else 401 (only ``/health`` stays open, and then says only "ok": the API's
   description, ``/docs`` and ``/openapi.json``, needs the token too);
4. a body's ``Content-Type`` is the endpoint's (``application/octet-stream`` for uploads,
   ``application/json`` for the rest), else 415;
5. a body over ``--max-request-mb`` gets 413 by its ``Content-Length`` or while it streams;
   bodies being received count against a budget of bytes in flight (``--max-inflight-mb``), 503
   with ``Retry-After`` past it; a body that stalls ``--read-timeout`` seconds between two
   chunks, or is not all in within 4 times that, gets 408 and the connection is closed.

:class:`TimedH11Protocol` closes a connection whose request headers are not complete within the
read timeout (uvicorn itself waits for headers for ever), and answers a request that finds
``--max-connections`` connections open, or as many requests in flight, 503 (uvicorn's own
``limit_concurrency`` answers that in plain text). Every refusal is ``{"error": ...}`` JSON
naming the limit and its option.
"""

from __future__ import annotations

import asyncio
import contextvars
import hmac
import json
import math
import time
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

from baseplace.serve.state import ServeSettings, ServiceState

UPLOAD_TYPE = "application/octet-stream"
JSON_TYPE = "application/json"
OPEN_PATHS = ("/health",)
"""Paths answered without the token: liveness, no data."""

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")

CLIENT: contextvars.ContextVar[str] = contextvars.ContextVar("baseplace_client", default="unknown")
"""The client of the request being answered: the peer's address (its port changes with each
connection). The service's queues are shared out by it. Forwarded-for headers are not trusted:
behind a reverse proxy every client is the proxy."""


def excerpt(text: str, limit: int = 80) -> str:
    """A short, escaped piece of client-sent text for an error line (never the whole input)."""
    cut = text[:limit]
    shown = cut.encode("unicode_escape").decode("ascii")
    return repr(shown) + (f" (+{len(text) - limit} more characters)" if len(text) > limit else "")


def host_name(host: str) -> str:
    """The name part of a Host header (``[::1]:8000`` -> ``[::1]``, ``a.b:80`` -> ``a.b``), lower case."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[: host.find("]") + 1] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def allowed_hosts(settings: ServeSettings) -> frozenset[str]:
    """The host names the service answers to: loopback, the bound address, and ``--allow-host``."""
    bound = settings.host.lower()
    bound = f"[{bound}]" if ":" in bound and not bound.startswith("[") else bound
    return frozenset((*LOOPBACK_NAMES, bound, *(host_name(h) for h in settings.allow_hosts)))


def authorized(headers: dict[bytes, bytes], token: str | None) -> bool:
    """True with no token configured, or when ``Authorization: Bearer TOKEN`` matches (constant time)."""
    if token is None:
        return True
    scheme, _, given = headers.get(b"authorization", b"").partition(b" ")
    return scheme.lower() == b"bearer" and hmac.compare_digest(given.strip(), token.encode())


def upload_path(path: str) -> bool:
    """True for the endpoints whose body is a file: ``/scenes`` and ``/scenes/{id}/grid``."""
    parts = path.strip("/").split("/")
    return parts == ["scenes"] or (len(parts) == 3 and parts[0] == "scenes" and parts[2] == "grid")


class _Refused(Exception):
    def __init__(self, status: int, message: str, headers: tuple[tuple[bytes, bytes], ...] = ()) -> None:
        super().__init__(message)
        self.status, self.headers = status, headers


class Guard:
    """ASGI middleware: host, origin, token, content type, body size, body time, bytes in flight."""

    def __init__(self, app: Any, settings: ServeSettings, state: ServiceState) -> None:
        self.app = app
        self.settings = settings
        self.state = state
        self.hosts = allowed_hosts(settings)

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        """Check the request, then pass it on with its body counted and timed."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        self.state.requests += 1
        peer = scope.get("client")
        CLIENT.set(str(peer[0]) if peer else "unknown")
        t0 = time.perf_counter()
        headers = {k.lower(): v for k, v in scope.get("headers", [])}
        reserved = 0
        try:
            length = self._check(scope, headers)
            reserved = self._reserve(length)
        except _Refused as exc:
            await send_error(send, exc.status, str(exc), exc.headers)
            return
        received = 0
        body_done = scope["method"] in ("GET", "HEAD", "DELETE", "OPTIONS")
        s = self.settings
        body_deadline = time.monotonic() + 4 * s.read_timeout_s
        started = False

        async def limited_receive() -> dict[str, Any]:
            nonlocal received, reserved, body_done
            if body_done:  # the body is in: the app only listens for a disconnect
                return dict(await receive())
            wait = min(s.read_timeout_s, body_deadline - time.monotonic())
            try:
                message: dict[str, Any] = await asyncio.wait_for(receive(), max(wait, 0.0))
            except asyncio.TimeoutError:
                raise _Refused(408, _slow_body(s.read_timeout_s, received), _CLOSE) from None
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                body_done = not message.get("more_body", False)
                if received > s.max_request_bytes:
                    raise _Refused(413, _too_large(s.max_request_bytes, received, streamed=True), _CLOSE)
                if received > reserved:  # a body without Content-Length: counted as it comes
                    more = received - reserved
                    if self.state.inflight_bytes + more > s.max_inflight_bytes:
                        raise _Refused(503, _busy(s), (*_CLOSE, _retry_after(s)))
                    self.state.inflight_bytes += more
                    reserved = received
            else:
                body_done = True
            return message

        async def tracking_send(message: dict[str, Any]) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
                elapsed = f"{(time.perf_counter() - t0) * 1e3:.2f}".encode()
                message = {
                    **message,
                    "headers": [*message.get("headers", []), (b"x-server-time-ms", elapsed)],
                }
            await send(message)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _Refused as exc:
            if not started:
                await send_error(send, exc.status, str(exc), exc.headers)
        finally:
            self.state.inflight_bytes -= reserved

    def _check(self, scope: dict[str, Any], headers: dict[bytes, bytes]) -> int:
        """The declared body length after the checks 1-5 of the module's list (raises :class:`_Refused`)."""
        s = self.settings
        host = headers.get(b"host", b"").decode("latin-1")
        if host_name(host) not in self.hosts:
            raise _Refused(400, f"Host {excerpt(host)} is not a name of this service; valid: "
                                f"{', '.join(sorted(self.hosts))} (serve --allow-host)")  # fmt: skip
        origin = headers.get(b"origin")
        if origin is not None:
            text = origin.decode("latin-1")
            same = text.lower() in (f"http://{host}".lower(), f"https://{host}".lower())
            if not same and text not in s.allow_origins:
                raise _Refused(403, f"cross-site request from origin {excerpt(text)} refused "
                                    "(serve --allow-origin to allow one)")  # fmt: skip
        path = scope.get("path", "")
        if path not in OPEN_PATHS and not authorized(headers, s.token):
            raise _Refused(401, "missing or wrong API token: send 'Authorization: Bearer TOKEN' "
                                "(serve --token or $BASEPLACE_TOKEN)", ((b"www-authenticate", b"Bearer"),))  # fmt: skip
        declared = headers.get(b"content-length", b"")
        if declared and not declared.isdigit():
            raise _Refused(400, f"Content-Length {excerpt(declared.decode('latin-1'))} is not a number")
        length = int(declared) if declared else 0
        chunked = b"chunked" in headers.get(b"transfer-encoding", b"").lower()
        if scope["method"] in ("POST", "PUT", "PATCH") or length or chunked:
            want = UPLOAD_TYPE if upload_path(path) else JSON_TYPE
            given = headers.get(b"content-type", b"").decode("latin-1").split(";")[0].strip().lower()
            if given != want:
                shown = excerpt(given) if given else "none"
                raise _Refused(415, f"Content-Type {shown} is not accepted here; send {want}")
        if length > s.max_request_bytes:
            raise _Refused(413, _too_large(s.max_request_bytes, length), _CLOSE)
        return length

    def _reserve(self, length: int) -> int:
        """Count a declared body against the bytes in flight before it is read (503 past the budget)."""
        if length and self.state.inflight_bytes + length > self.settings.max_inflight_bytes:
            raise _Refused(503, _busy(self.settings), (*_CLOSE, _retry_after(self.settings)))
        self.state.inflight_bytes += length
        return length


_CLOSE = ((b"connection", b"close"),)


def _retry_after(settings: ServeSettings) -> tuple[bytes, bytes]:
    return (b"retry-after", str(max(1, math.ceil(settings.read_timeout_s))).encode())


def _too_large(limit: int, size: int, streamed: bool = False) -> str:
    what = f"more than {size}" if streamed else f"{size}"
    return f"request body of {what} bytes is over the limit of {limit} bytes (serve --max-request-mb)"


def _busy(settings: ServeSettings) -> str:
    return (
        f"the service is receiving {settings.max_inflight_bytes} bytes of request bodies already "
        "(serve --max-inflight-mb); try again shortly"
    )


def _slow_body(timeout: float, received: int) -> str:
    return (
        f"the request body stalled for {timeout:g} s or took over {4 * timeout:g} s after {received} bytes "
        "(serve --read-timeout)"
    )


async def send_error(
    send: Any, status: int, error: str, headers: tuple[tuple[bytes, bytes], ...] = ()
) -> None:
    """Answer ``{"error": error}`` with ``status`` straight from the middleware."""
    body = json.dumps({"error": error}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                            *headers]})  # fmt: skip
    await send({"type": "http.response.body", "body": body})


def _too_many_connections(limit: int) -> Any:
    async def refuse(scope: dict[str, Any], receive: Any, send: Any) -> None:
        message = (f"the service has {limit} connections or requests open already (serve --max-connections); "
                   "try again shortly")  # fmt: skip
        await send_error(send, 503, message, (*_CLOSE, (b"retry-after", b"1")))

    return refuse


class TimedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol that closes a connection whose request headers take over ``header_timeout`` s.

    The timer runs from the connection's start and again after each response, and stops when a
    request's headers are complete; the body's time is :class:`Guard`'s.
    """

    header_timeout: float = 10.0
    max_connections: int | None = None
    """Open connections, and requests in flight, past which a request is answered 503 JSON (as
    uvicorn's ``limit_concurrency`` counts them)."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """Start the first request's header timer."""
        super().connection_made(transport)  # type: ignore[arg-type]
        self._header_timer: asyncio.TimerHandle | None = None
        self._service = self.app
        self._arm()

    def _arm(self) -> None:
        if getattr(self, "_header_timer", None) is not None:
            self._header_timer.cancel()  # type: ignore[union-attr]
        self._waiting_after = self.cycle  # the request before the one whose headers are awaited
        self._header_timer = self.loop.call_later(self.header_timeout, self._headers_too_slow)

    def _headers_too_slow(self) -> None:
        self._header_timer = None
        if self.cycle is self._waiting_after and not self.transport.is_closing():
            self.transport.close()

    def handle_events(self) -> None:
        """Read the events; a new request's complete headers stop the timer.

        A request that arrives while the connections or the requests in flight are at
        ``max_connections`` goes to :func:`_too_many_connections` instead of the service
        (uvicorn takes ``self.app`` when it reads the request's headers, in this call).
        """
        limit = self.max_connections
        full = limit is not None and (len(self.connections) > limit or len(self.tasks) >= limit)
        self.app = _too_many_connections(limit or 0) if full else self._service
        super().handle_events()
        if self._header_timer is not None and self.cycle is not self._waiting_after:
            self._header_timer.cancel()
            self._header_timer = None

    def on_response_complete(self) -> None:
        """Time the next request's headers (armed first: a pipelined request may start at once)."""
        if not self.transport.is_closing():
            self._arm()
        super().on_response_complete()

    def connection_lost(self, exc: Exception | None) -> None:
        """Stop the timer with the connection."""
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None
        super().connection_lost(exc)
