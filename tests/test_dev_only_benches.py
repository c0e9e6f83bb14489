"""The development benches of issue 25 refuse held-out seeds, in one line, before any work."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from baseplace.errors import InputError

BENCH = Path(__file__).resolve().parents[1] / "bench"
sys.path.insert(0, str(BENCH))


def test_irm_pool_dev_refuses_a_held_out_seed():
    proc = subprocess.run([sys.executable, str(BENCH / "irm_pool_dev.py"), "--label", "x", "--seeds", "0", "17"],
                          capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=120)  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "development seeds only: 0, 1, 2" in proc.stderr.strip().splitlines()[-1]


def test_find_rate_refusals_refuses_a_source_file_with_held_out_scenes(tmp_path):
    from find_rate_refusals import main

    source = tmp_path / "held_out.json"
    source.write_text(json.dumps({"scenes": [{"scene": {"seed": 25000}}, {"scene": {"seed": 25100}}]}))
    with pytest.raises(InputError, match="development seeds only"):
        main(["--from", str(source), "--out", str(tmp_path / "out.json")])
    assert not (tmp_path / "out.json").exists()


def test_find_rate_refusals_refuses_a_seed_not_in_its_sources(tmp_path):
    from find_rate_refusals import main

    source = tmp_path / "dev.json"
    source.write_text(json.dumps({"scenes": [{"scene": {"seed": 25000}}]}))
    with pytest.raises(InputError, match=r"seeds \[25001\] are not in the source files"):
        main(["--from", str(source), "--out", str(tmp_path / "out.json"), "--seeds", "25001"])
    assert not (tmp_path / "out.json").exists()
