"""A small Python client of ``baseplace serve`` (httpx): one method per endpoint, the CLI's JSON back.

with Client("http://127.0.0.1:8000") as c:
scene = c.upload_scene("room.ply")
result = c.place(scene, ["1.6 0 1.05 0 1.5708 0"])
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx

from baseplace.errors import BaseplaceError, InputError, NothingFoundError

UPLOAD = {"Content-Type": "application/octet-stream"}
"""The content type of a file upload (the service refuses any other with 415)."""


class ServiceError(BaseplaceError):
    """The service answered with an error; ``status`` is the HTTP status, the message its one line."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


class Client:
    """Talks to a running service.

    Args:
        url: the service's base URL.
        timeout_s: per-request time limit of the client [s].
        token: the service's API token (default ``$BASEPLACE_TOKEN``), sent as
            ``Authorization: Bearer TOKEN``.
    """

    def __init__(
        self,
        url: str = "http://127.0.0.1:8000",
        timeout_s: float = 60.0,
        token: str | None = None,
        **httpx_args: Any,
    ) -> None:
        import os

        token = token if token is not None else os.environ.get("BASEPLACE_TOKEN") or None
        headers = {**httpx_args.pop("headers", {})}
        if token is not None:
            headers["Authorization"] = f"Bearer {token}"
        self._http = httpx.Client(base_url=url, timeout=timeout_s, headers=headers, **httpx_args)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection pool."""
        self._http.close()

    def _answer(self, response: httpx.Response) -> dict[str, Any]:
        try:
            body: dict[str, Any] = response.json()
        except ValueError:
            body = {"error": response.text.strip()[:200] or f"HTTP {response.status_code}"}
        if response.status_code >= 400:
            error = str(body.get("error", f"HTTP {response.status_code}"))
            if response.status_code in (400, 404, 413, 415, 422):
                raise InputError(error)
            raise ServiceError(error, response.status_code)
        return body

    def _post(self, path: str, **fields: Any) -> dict[str, Any]:
        return self._answer(self._http.post(path, json={k: v for k, v in fields.items() if v is not None}))

    def health(self) -> dict[str, Any]:
        """GET /health."""
        return self._answer(self._http.get("/health"))

    def upload_scene(
        self,
        cloud: str | Path | bytes,
        format: str | None = None,
        transform: str | None = None,
        floor: float | None = None,
    ) -> str:
        """Upload a cloud file (or its bytes with ``format``); returns the scene id.

        ``transform`` (the up vector "ux uy uz" or 16 numbers of ``T_world_sensor``) and ``floor``
        [m] are the CLI's ``--transform`` and ``--floor``.
        """
        if isinstance(cloud, bytes):
            data, fmt = cloud, format
        else:
            path = Path(cloud)
            data, fmt = path.read_bytes(), format or path.suffix.lstrip(".").lower()
        if not fmt:
            raise InputError("give the cloud's format: ply, pcd, npy or xyz")
        extra = {"transform": transform, "floor": floor}
        params = {"format": fmt, **{k: v for k, v in extra.items() if v is not None}}
        return str(
            self._answer(self._http.post("/scenes", params=params, content=data, headers=UPLOAD))["scene_id"]
        )

    def upload_grid(
        self, scene_id: str, image: str | Path, resolution: float, **yaml_fields: Any
    ) -> dict[str, Any]:
        """Attach a map_server grid (image file + its YAML fields, origin as origin_x/origin_y/origin_yaw)."""
        path = Path(image)
        params = {"resolution": resolution, "format": path.suffix.lstrip(".").lower(), **yaml_fields}
        return self._answer(
            self._http.post(
                f"/scenes/{scene_id}/grid", params=params, content=path.read_bytes(), headers=UPLOAD
            )
        )

    def segmentation(self, scene_id: str) -> dict[str, Any]:
        """The scene's ``baseplace segment --json``."""
        return self._answer(self._http.get(f"/scenes/{scene_id}/segmentation"))

    def place(
        self, scene_id: str, targets: list[str], *, raise_if_none: bool = False, **options: Any
    ) -> dict[str, Any]:
        """``baseplace place --json`` (options: the CLI's, with underscores); ``found`` is False if none.

        With ``raise_if_none`` a run that found nothing raises :class:`NothingFoundError` instead.
        """
        out = self._post("/place", scene_id=scene_id, targets=targets, **options)
        if raise_if_none and out.get("found") is False:
            raise NothingFoundError(str(out.get("error")))
        return out

    def explain(self, base: str, target: str | None = None, **options: Any) -> dict[str, Any]:
        """``baseplace explain --json`` (options: ``scene_id``, ``grasp_point`` and the CLI's, with underscores)."""
        return self._post("/explain", base=base, target=target, **options)

    def candidates(self, scene_id: str, object: str, **options: Any) -> dict[str, Any]:
        """``baseplace candidates --json`` on a scene with a grid."""
        return self._post("/candidates", scene_id=scene_id, object=object, **options)

    def reach(self, targets: list[str], bases: list[str], **options: Any) -> dict[str, Any]:
        """``baseplace reach --json`` on the robot's default map."""
        return self._post("/reach", targets=targets, bases=bases, **options)

    def navigate(self, scene_id: str, start: str, goal: str, **options: Any) -> dict[str, Any]:
        """``baseplace navigate --json``."""
        return self._post("/navigate", scene_id=scene_id, start=start, goal=goal, **options)

    def surface_map(self, polygon: str, height: float, **options: Any) -> dict[str, Any]:
        """``baseplace surface-map --json``; its ``surface_map_id`` names it for :meth:`surface_samples`."""
        return self._post("/surface-map", polygon=polygon, height=height, **options)

    def surface_samples(self, surface_map_id: str, **options: Any) -> dict[str, Any]:
        """``baseplace surface-sample --json``."""
        return self._post("/surface-samples", surface_map_id=surface_map_id, **options)
