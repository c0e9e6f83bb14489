"""Run the service on uvicorn: loopback by default, graceful shutdown on SIGINT/SIGTERM."""

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


def serve(settings: ServeSettings | None = None, log_level: str = "warning") -> None:
    """Serve until SIGINT/SIGTERM: new connections stop, requests in flight finish (within the time limit).

    The robots named in ``settings.robots`` are warmed before the port opens.
    """
    s = settings or ServeSettings()
    app = create_app(s)
    import uvicorn

    config = uvicorn.Config(app, host=s.host, port=s.port, log_level=log_level, lifespan="on",
                            timeout_graceful_shutdown=max(1, int(s.timeout_s)), access_log=False)  # fmt: skip
    uvicorn.Server(config).run()
