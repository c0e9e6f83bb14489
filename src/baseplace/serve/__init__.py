"""The placement service (``baseplace serve``) and its Python client (issue 18).

:func:`create_app` builds the FastAPI app, :func:`serve` runs it on uvicorn, :class:`Client` talks
to it. FastAPI and uvicorn come with the ``serve`` extra (``pip install baseplace[serve]``).
"""

from __future__ import annotations

from typing import Any

__all__ = ["Client", "ServeSettings", "create_app", "serve"]


def __getattr__(name: str) -> Any:
    if name == "Client":
        from baseplace.serve.client import Client

        return Client
    if name == "ServeSettings":
        from baseplace.serve.state import ServeSettings

        return ServeSettings
    if name in ("create_app", "serve"):
        from baseplace.serve import server

        return getattr(server, name) if name == "serve" else server.create_app
    raise AttributeError(f"module 'baseplace.serve' has no attribute {name!r}")
