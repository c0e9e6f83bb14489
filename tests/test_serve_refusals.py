"""Every refusal is the documented ``{"error": ...}`` JSON, and the API's description needs the token (issue 28)."""

from __future__ import annotations

import socket
import threading
import time

import httpx
import pytest

from conftest import free_port

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from fastapi.testclient import TestClient

from test_serve import make_app

TOKEN = "a-token-of-twenty-chars"


def test_a_request_over_the_connection_limit_gets_503_json(tiago, tiago_map):
    from baseplace.serve.server import uvicorn_server

    port = free_port()
    app = make_app(tiago, tiago_map, port=port, max_connections=2, allow_hosts=())
    server = uvicorn_server(app, app.state.service.settings)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.time() + 30
    while not server.started and time.time() < deadline:
        time.sleep(0.05)
    url = f"http://127.0.0.1:{port}"
    try:
        held = [socket.create_connection(("127.0.0.1", port)) for _ in range(2)]  # the limit, idle
        time.sleep(0.3)
        r = httpx.get(url + "/health", timeout=10)
        assert r.status_code == 503, r.text
        assert r.headers["content-type"].startswith("application/json"), (r.headers, r.text)
        assert "--max-connections" in r.json()["error"] and r.headers["retry-after"].isdigit()
        for s in held:
            s.close()
        time.sleep(0.3)
        assert httpx.get(url + "/health", timeout=10).status_code == 200  # the bound, not a lock-out
    finally:
        server.should_exit = True
        thread.join(30)


def test_the_api_description_needs_the_token_when_one_is_set(tiago, tiago_map):
    with TestClient(make_app(tiago, tiago_map, token=TOKEN), raise_server_exceptions=False) as c:
        for path in ("/openapi.json", "/docs", "/docs/oauth2-redirect"):
            r = c.get(path)
            assert r.status_code == 401, (path, r.status_code)
            assert "token" in r.json()["error"]
        auth = {"authorization": f"Bearer {TOKEN}"}
        assert c.get("/openapi.json", headers=auth).json()["paths"]
        assert c.get("/docs", headers=auth).status_code == 200
        assert c.get("/health").json() == {"status": "ok"}  # liveness stays open, and says nothing else
