"""Fuzz the service's endpoints from its own OpenAPI document (schemathesis, issue 28).

Every operation gets a bounded number of generated requests, valid and invalid, through the
in-process ASGI app (loopback, no socket): no answer may be a 500, and every answer is JSON.
The default run keeps under a minute; ``-m slow`` runs ten times as many examples.
"""

from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, Phase, given, settings

pytest.importorskip("fastapi")
schemathesis = pytest.importorskip("schemathesis")

from test_serve import make_app  # noqa: E402  (needs FastAPI)

SEEN: dict[str, int] = {"requests": 0, "500": 0, "non_json": 0}


def _fuzz(app, examples: int) -> None:
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    failures: list[str] = []
    for result in schema.get_all_operations():
        operation = result.ok()

        @settings(max_examples=examples, deadline=None, phases=[Phase.explicit, Phase.generate],
                  suppress_health_check=list(HealthCheck), database=None)  # fmt: skip
        @given(case=operation.as_strategy())
        def one(case) -> None:
            response = case.call(headers={"host": "testserver"})
            SEEN["requests"] += 1
            where = f"{case.method} {case.formatted_path} -> {response.status_code}"
            if response.status_code >= 500 and response.status_code not in (503, 504):
                SEEN["500"] += 1
                failures.append(f"{where}: {response.text[:200]}")
            try:
                json.loads(response.content)
            except ValueError:
                SEEN["non_json"] += 1
                failures.append(f"{where}: not JSON: {response.text[:200]!r}")

        one()
    print(
        f"fuzz: {SEEN['requests']} requests, {SEEN['500']} answers of 500, {SEEN['non_json']} non-JSON bodies"
    )
    assert not failures, failures[:10]


def test_every_endpoint_fuzzed_answers_json_and_never_500(tiago, tiago_map):
    _fuzz(make_app(tiago, tiago_map, timeout_s=5.0), examples=50)


@pytest.mark.slow
def test_every_endpoint_fuzzed_long(tiago, tiago_map):
    _fuzz(make_app(tiago, tiago_map, timeout_s=10.0), examples=250)
