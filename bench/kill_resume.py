"""Kill default map builds at random moments, resume them, compare with an uninterrupted build (issue 15).

Protocol (fixed before any run): one uninterrupted ``baseplace build-map`` (TIAGo, 5e7 samples,
seed 0 by default) is the reference; its wall time is T. Each trial starts the same command
(default checkpoints: every 30 s of build time) and SIGKILLs it, either at a time drawn
uniformly from (1 s, T) (a "random" trial), or as soon as the temporary file of the map save
appears (a "save" trial: every fourth trial, so 5 of 20). Then the same command runs again to the
end. A trial passes if the resumed run exits 0, its map's arrays equal the reference's exactly,
no temporary or lock file is left, and the work lost is at most 30 s. The wall time lost runs
from the last durable state (the checkpoint file's mtime, or the map's for a kill after the save)
or from the start of the killed run when it had written neither, to the kill; the work lost is
that less, for a run with no checkpoint yet, the run's start-up and save overhead (the reference
run's wall time less the build time it reports). Both are recorded.

Usage: python bench/kill_resume.py [--trials 20] [--samples 5e7] [--seed 0] [--out FILE]
Writes the result JSON (default bench/results/kill_resume.json).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from baseplace.reachability.storage import load_map
from baseplace_experiments.results import write_results
from common import STARTED

MAX_LOST_S = 30.0


def command(out: Path, samples: int, seed: int) -> list[str]:
    return [sys.executable, "-m", "baseplace.cli", "build-map", "--robot", "tiago", "--samples", str(samples),
            "--seed", str(seed), "--out", str(out), "--json"]  # fmt: skip


def run_to_end(out: Path, samples: int, seed: int) -> tuple[int, float, str, float]:
    """Exit code, wall time, stderr tail and the build time the CLI reports (0 if it failed)."""
    t0 = time.monotonic()
    proc = subprocess.run(
        command(out, samples, seed), capture_output=True, text=True, stdin=subprocess.DEVNULL
    )
    build_s = float(json.loads(proc.stdout)["build_time_s"]) if proc.returncode == 0 else 0.0
    return proc.returncode, time.monotonic() - t0, proc.stderr[-500:], build_s


def trial(work: Path, kind: str, kill_at: float, samples: int, seed: int) -> dict[str, object]:
    out = work / "m.rmap"
    ckpt = work / "m.rmap.partial"
    t0 = time.monotonic()
    wall0 = time.time()
    proc = subprocess.Popen(command(out, samples, seed), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            stdin=subprocess.DEVNULL)  # fmt: skip
    killed_in = "run"
    while proc.poll() is None:
        now = time.monotonic() - t0
        # the map's temporary file (".m.rmap.XXXXXXXX.tmp"), not a checkpoint's (".m.rmap.partial...")
        saving = any(
            p.name.startswith(".m.rmap.")
            and not p.name.startswith(".m.rmap.partial")
            and p.name.endswith(".tmp")
            for p in work.iterdir()
        )
        if (kind == "random" and now >= kill_at) or (kind == "save" and saving):
            kill_wall = time.time()
            proc.send_signal(signal.SIGKILL)
            killed_in = "save" if saving else "run"
            break
        time.sleep(0.01)
    proc.wait()
    if proc.returncode == 0:  # finished before the kill moment
        return {"kind": kind, "kill_at_s": round(kill_at, 2), "killed": False, "lost_s": 0.0}
    durable = [p.stat().st_mtime for p in (ckpt, out) if p.exists()]
    lost = kill_wall - (max(durable) if durable else wall0)
    code, resume_s, err, _ = run_to_end(out, samples, seed)
    leftovers = sorted(p.name for p in work.iterdir() if p.name != "m.rmap")
    return {
        "kind": kind,
        "kill_at_s": round(kill_wall - wall0, 2),
        "killed": True,
        "killed_in": killed_in,
        "had_checkpoint": ckpt.exists() or bool(durable),
        "lost_s": round(lost, 2),
        "resume_exit": code,
        "resume_s": round(resume_s, 1),
        "resume_error": err if code else "",
        "leftovers": leftovers,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--samples", type=float, default=5e7)
    parser.add_argument("--seed", type=int, default=0, help="build seed")
    parser.add_argument("--rng", type=int, default=15, help="seed of the kill moments")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "kill_resume.json"))
    args = parser.parse_args()
    samples = int(args.samples)
    rng = np.random.default_rng(args.rng)
    with tempfile.TemporaryDirectory(prefix="kill_resume-") as tmp:
        root = Path(tmp)
        (root / "ref").mkdir()
        code, ref_s, err, ref_build_s = run_to_end(root / "ref" / "m.rmap", samples, args.seed)
        # process start-up (imports, loading the compiled kernels) and the final save: not sampling
        overhead_s = ref_s - ref_build_s
        if code != 0:
            raise SystemExit(f"reference build failed: {err}")
        ref = load_map(root / "ref" / "m.rmap")
        trials = []
        for i in range(args.trials):
            kind = "save" if i % 4 == 3 else "random"
            kill_at = float(rng.uniform(1.0, ref_s))
            work = root / f"t{i}"
            work.mkdir()
            r = trial(work, kind, kill_at, samples, args.seed)
            if r["killed"] and r["resume_exit"] == 0:
                got = load_map(work / "m.rmap")
                r["identical"] = bool(
                    np.array_equal(got.cells, ref.cells) and np.array_equal(got.counts, ref.counts)
                )
            if r[
                "killed"
            ]:  # sampling work lost: wall time lost less the start-up of a run with no checkpoint
                lost_s = float(r["lost_s"])  # type: ignore[arg-type]
                r["lost_work_s"] = round(lost_s - (0.0 if r["had_checkpoint"] else overhead_s), 2)
            r["passed"] = (not r["killed"]) or (
                r.get("identical", False)
                and r["resume_exit"] == 0
                and not r["leftovers"]
                and r["lost_work_s"] <= MAX_LOST_S
            )
            trials.append(r)
            print(json.dumps(r), flush=True)
    killed = [t for t in trials if t["killed"]]
    result = {
        "protocol": __doc__.split("\n\n")[1].replace("\n", " "),
        "samples": samples,
        "seed": args.seed,
        "reference_wall_s": round(ref_s, 1),
        "trials": trials,
        "killed": len(killed),
        "killed_during_save": sum(t.get("killed_in") == "save" for t in killed),
        "passed": sum(bool(t["passed"]) for t in trials),
        "reference_build_s": round(ref_build_s, 1),
        "overhead_s": round(overhead_s, 1),
        "max_lost_s": max((float(t["lost_s"]) for t in killed), default=0.0),  # type: ignore[arg-type]
        "max_lost_work_s": max((float(t["lost_work_s"]) for t in killed), default=0.0),  # type: ignore[arg-type]
        "cpus": os.cpu_count(),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    write_results(args.out, result, STARTED, used_seeds=[args.seed, args.rng])
    print(f"{result['passed']}/{len(trials)} passed; {len(killed)} killed ({result['killed_during_save']} during the "
          f"save); max work lost {result['max_lost_work_s']} s (wall {result['max_lost_s']} s); "
          f"reference {ref_s:.1f} s")  # fmt: skip
    return 0 if result["passed"] == len(trials) else 1


if __name__ == "__main__":
    sys.exit(main())
