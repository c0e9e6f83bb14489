"""The jobs layer: one function per job, typed inputs, one typed, versioned report.

Front ends (the CLI, the service, the viewer) build the inputs, call a job and show its report;
they do no work of their own. Jobs print nothing and never exit: they raise
:class:`~baseplace.errors.InputError` for bad input and :class:`~baseplace.jobs.report.NoResultError`
(a :class:`~baseplace.errors.NothingFoundError` carrying the partial report) when they find nothing.
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import TYPE_CHECKING, Any

from baseplace.jobs.report import SCHEMA_VERSION, NoResultError, Report, RobotRef

if TYPE_CHECKING:
    from baseplace.jobs.explain import ExplainJob, ExplainReport, explain_job


@cache
def result_schema() -> dict[str, Any]:
    """The JSON Schema of every report (``result.schema.json``, shipped with the package)."""
    text = resources.files("baseplace.jobs").joinpath("result.schema.json").read_text()
    schema: dict[str, Any] = json.loads(text)
    return schema


def __getattr__(name: str) -> Any:
    """The explain job's names, imported on first use: a job imports what it uses alone."""
    if name in ("ExplainJob", "ExplainReport", "explain_job"):
        from baseplace.jobs import explain

        return getattr(explain, name)
    raise AttributeError(f"module 'baseplace.jobs' has no attribute {name!r}")


__all__ = [
    "SCHEMA_VERSION",
    "ExplainJob",
    "ExplainReport",
    "NoResultError",
    "Report",
    "RobotRef",
    "explain_job",
    "result_schema",
]
