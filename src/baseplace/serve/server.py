"""Run the service on uvicorn: loopback by default, limits on connections and reads, shutdown within the time limit."""

from __future__ import annotations

from typing import Any

from baseplace.errors import InputError
from baseplace.serve.state import ServeSettings


def create_app(settings: ServeSettings | None = None, state: Any = None) -> Any:
    """The FastAPI app of the service (see :mod:`baseplace.serve.app`); ``state``: a prepared ServiceState."""
    try:
        from baseplace.serve.app import create_app as make
    except ImportError as exc:
        raise InputError(
            f"the service needs FastAPI and uvicorn: pip install 'baseplace[serve]' ({exc})"
        ) from None
    return make(settings, state)


def uvicorn_server(app: Any, settings: ServeSettings, log_level: str = "warning") -> Any:
    """A uvicorn server of ``app`` with the service's limits.

    A request finding ``max_connections`` connections open gets 503 JSON (the protocol's check,
    not uvicorn's plain-text one); a connection whose request headers are not in
    within ``read_timeout_s`` is closed (:class:`~baseplace.serve.guard.TimedH11Protocol`); an
    idle keep-alive connection after 5 s; headers over 16 KiB get 400 (h11's limit). On SIGINT or
    SIGTERM every job is cancelled at once (it stops at its next deadline check), requests in
    flight are answered, and the process ends within the time limit.
    """
    import uvicorn

    from baseplace.serve.guard import TimedH11Protocol

    protocol = type("ServiceH11Protocol", (TimedH11Protocol,),
                    {"header_timeout": settings.read_timeout_s, "max_connections": settings.max_connections})  # fmt: skip
    config = uvicorn.Config(app, host=settings.host, port=settings.port, log_level=log_level, lifespan="on",
                            http=protocol, timeout_keep_alive=5,
                            h11_max_incomplete_event_size=16 * 1024,
                            timeout_graceful_shutdown=max(1, int(settings.timeout_s)), access_log=False)  # fmt: skip
    state = app.state.service

    class Server(uvicorn.Server):
        def handle_exit(self, sig: int, frame: Any) -> None:
            state.stop_jobs()
            super().handle_exit(sig, frame)

    return Server(config)


def serve(settings: ServeSettings | None = None, log_level: str = "warning") -> None:
    """Serve until SIGINT/SIGTERM: new connections stop, jobs are cancelled, requests in flight are answered.

    The robots named in ``settings.robots`` are warmed before the port opens.
    """
    s = settings or ServeSettings()
    uvicorn_server(create_app(s), s, log_level).run()
