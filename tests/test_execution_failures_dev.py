"""bench/execution_failures_dev.py runs development seeds only (the protocol's held-out seeds never)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from baseplace.errors import InputError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))


@pytest.mark.parametrize("seeds", [["17"], ["0", "14"], ["3"]])
def test_refuses_seeds_outside_dev(seeds: list[str]) -> None:
    from execution_failures_dev import main

    with pytest.raises(InputError, match="development seeds only"):
        main(["--seeds", *seeds])
