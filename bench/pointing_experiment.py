"""Seed 004's pointing selection on generated RGB-D scenes (issue 30); protocol: docs/protocols/pointing_v3.md.

Usage: ``python bench/pointing_experiment.py --split dev|held-out [--results FILE.json] [--limit N]``.
The results file records the protocol file's commit (its last commit before the run).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from baseplace_experiments.pointing_experiment import SEEDS, run_scene, summarize
from baseplace_experiments.results import RunClock, fixed_protocol, write_results

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = "docs/protocols/pointing_v3.md"


def protocol_commit() -> str | None:
    """The last commit that changed the protocol file, or None outside git."""
    try:
        out = subprocess.run(["git", "log", "-1", "--format=%H", "--", PROTOCOL], cwd=ROOT, capture_output=True,
                             text=True, timeout=10, check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return out or None


def main(argv: list[str] | None = None) -> int:
    """Run the split's scenes, print the summary, write the results file."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--split", choices=["dev", "held-out"], required=True)
    parser.add_argument("--results", default=None, help="results JSON (bench/results/...)")
    parser.add_argument("--limit", type=int, default=None, help="only the first N seeds (a quick check)")
    args = parser.parse_args(argv)
    protocol_file = fixed_protocol(PROTOCOL, args.split)  # before any work: a held-out run needs it clean
    clock = RunClock()
    seeds = list(SEEDS.seeds(args.split))[: args.limit]
    rows = []
    for k, seed in enumerate(seeds):
        rows.append(run_scene(seed))
        print(f"\r{k + 1}/{len(seeds)}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    result = {"summary": summarize(rows), "scenes": rows,
              "protocol_file": PROTOCOL, "protocol_commit": protocol_commit()}  # fmt: skip
    print(json.dumps(result["summary"], indent=1))
    if args.results:
        write_results(args.results, result, clock, seeds=SEEDS, split=args.split, used_seeds=seeds,
                      protocol_file=protocol_file)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
