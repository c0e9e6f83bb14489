"""Fuzz every loader and the pose math on the full budget (issue 9.3).

The targets and strategies are those of ``tests/fuzz_cases.py`` (the CI test ``tests/test_fuzz.py``
runs the same ones on a small, derandomized budget). Every target runs in its own worker process,
so a native crash (segfault, abort) costs that target only; the parent records how the worker
died and the last case it started. Per target the report counts cases and outcomes (loaded /
clean BaseplaceError / crash / hang / violated property), groups crashes by exception type and
the deepest baseplace frame (with the known or fixed bug they match, if any), counts loaded values that
break an invariant ("notes"), cases that wrote to the native stderr (libpng, octomap print there)
and cases that emitted Python warnings, and times the cases.

Hangs: a case past ``--case-timeout`` is interrupted by SIGALRM when it is in Python code. A hang
inside native code (HDF5 holds the GIL) cannot be interrupted; faulthandler then dumps the stack
and ends the worker after ``--native-timeout``, the parent counts that case as a hang, and
restarts the target with the next seed for the cases still to run (counts since the worker's last
save, at most 50 cases, are lost and run again).

Workers run with hypothesis' generate phase only (no shrinking: a crash is counted, not
minimized; ``tests/test_fuzz.py`` shrinks) from ``--seed``, under an address-space limit
(``--memory-gib``) so a runaway allocation becomes a MemoryError instead of taking the machine.
That cap is a safety net, not a pass: every case's growth of peak resident memory is measured
(``fuzz_cases.run_case``; reported per target as ``peak_memory_mib``), and a case that grows it
by more than ``MEMORY_MULTIPLE`` x its input bytes + ``MEMORY_SLACK`` counts as a crash
("MemoryBlowup"), even if it ended in a clean error (issue 15).

Usage: python bench/fuzz.py [--examples 10000] [--targets cloud_pcd,occupancy] [--jobs 2]
       [--seed 0] [--case-timeout 20] [--native-timeout 90] [--memory-gib 8] [--update]

Writes bench/results/fuzz.json (with --update: replaces only the targets run now).
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent / "tests"
RESULTS_FILE = HERE / "results" / "fuzz.json"
SAVE_EVERY = 50
MAX_RESTARTS = 25


# --- worker: one target in this process ---


def _worker(args: argparse.Namespace) -> None:
    sys.path.insert(0, str(TESTS))
    from hypothesis import Phase, given, seed, settings

    import fuzz_cases as fc

    limit = int(args.memory_gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    target = fc.TARGETS[args.worker]
    fc.prepare(target.name)
    out = Path(args.result)
    scratch = Path(tempfile.mkdtemp(prefix=f"scratch-{target.name}-", dir=out.parent))  # parent removes
    last_case = out.with_suffix(".last_case.txt")
    hang_dump = open(out.with_suffix(".hang.txt"), "w")

    # native libraries (libpng, octomap) print to file descriptor 2: count the cases that do
    sink = open(out.with_suffix(".stderr.txt"), "w+b")
    os.dup2(sink.fileno(), 2)

    outcomes: Counter[str] = Counter()
    crashes: dict[str, dict[str, Any]] = {}
    notes: dict[str, dict[str, Any]] = {}
    noisy: dict[str, Any] = {"cases": 0, "example": "", "output": ""}
    warned = 0
    times: list[float] = []
    peaks: list[int] = []
    start = time.perf_counter()

    def save(complete: bool, error: str = "") -> None:
        result = {
            "target": target.name,
            "doc": target.doc,
            "kind": target.kind,
            "complete": complete,
            "error": error,
            "cases": sum(outcomes.values()),
            "outcomes": {k: outcomes[k] for k in fc.OUTCOMES},
            "crashes": sorted(crashes.values(), key=lambda c: -c["count"]),
            "notes": sorted(notes.values(), key=lambda n: -n["count"])[:10],
            "native_stderr_cases": noisy,
            "warning_cases": warned,
            "seconds": round(time.perf_counter() - start, 1),
            "peak_memory_mib": {  # growth of peak resident memory per case (fuzz_cases.run_case)
                "max": round(max(peaks, default=0) / 2**20, 1),
                "median": round(sorted(peaks)[len(peaks) // 2] / 2**20, 1) if peaks else 0.0,
                "limit": f"{fc.MEMORY_MULTIPLE} x input + {fc.MEMORY_SLACK // 2**20} MiB",
            },
            "case_seconds": {
                "sum": sum(times),
                "max": max(times, default=0.0),
                "over_1s": sum(t > 1 for t in times),
            },
        }
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(result, indent=1))
        tmp.replace(out)

    @settings(fc.CI_SETTINGS, max_examples=args.examples, derandomize=False, phases=[Phase.generate])
    @seed(args.seed)
    @given(target.strategy)
    def one(case: Any) -> None:
        nonlocal warned
        text = fc.describe(case)
        last_case.write_text(text)
        before = sink.seek(0, 2)
        faulthandler.dump_traceback_later(args.native_timeout, exit=True, file=hang_dump)
        t = time.perf_counter()
        r = fc.run_case(target, case, scratch / "case", time_limit=args.case_timeout)
        times.append(time.perf_counter() - t)
        peaks.append(r.peak_bytes)
        faulthandler.cancel_dump_traceback_later()
        outcomes[r.outcome] += 1
        warned += r.warnings > 0
        if r.outcome in (fc.CRASH, fc.HANG, fc.VIOLATED):
            bug = fc.known_bug(target.name, r, include_fixed=True)
            entry = crashes.setdefault(
                r.signature,
                {"signature": r.signature, "outcome": r.outcome, "count": 0, "message": r.message,
                 "known_bug": bug.id if bug else None, "example": text},
            )  # fmt: skip
            entry["count"] += 1
        if r.note:
            key = r.note if len(r.note) < 60 else r.note[:60]
            notes.setdefault(key, {"note": r.note, "count": 0, "example": text})["count"] += 1
        after = sink.seek(0, 2)
        if after > before:
            noisy["cases"] += 1
            if not noisy["example"]:
                sink.seek(before)
                noisy["output"] = sink.read(min(after - before, 300)).decode(errors="replace")
                noisy["example"] = text
        if len(times) % SAVE_EVERY == 0:
            save(False)

    try:
        one()
    except BaseException as exc:  # hypothesis gave up, or the fuzz code itself broke
        save(False, f"{type(exc).__name__}: {str(exc).strip()[:300]}")
        raise
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    save(True)


# --- parent: run the workers, collect, report ---


def _native_hang(dump: str, timeout: float, target: str, case: str) -> dict[str, Any]:
    """A crash entry for a case stuck in native code, from faulthandler's dump of the stack."""
    import fuzz_cases as fc

    frames = re.findall(r'File "(.+)", line (\d+) in (\S+)', dump)  # most recent call first
    ours = [f for f in frames if "/baseplace/" in f[0]]

    def where(f: tuple[str, str, str]) -> str:
        return f"{f[0].split('/src/')[-1].split('site-packages/')[-1]}:{f[1]} {f[2]}"

    signature = f"Hang @ {where((ours or frames)[0])}" if frames else "Hang @ ?"
    message = f"native code did not return within {timeout:g} s" + (
        f" (in {where(frames[0])})" if frames else ""
    )
    bug = fc.known_bug(target, fc.Result(fc.HANG, signature, message), include_fixed=True)
    return {"signature": signature, "outcome": fc.HANG, "count": 1, "message": message,
            "known_bug": bug.id if bug else None, "example": case}  # fmt: skip


def _merge(total: dict[str, Any] | None, part: dict[str, Any]) -> dict[str, Any]:
    """Add the counts of one worker run to the target's total."""
    if total is None:
        return json.loads(json.dumps(part))
    total["cases"] += part.get("cases", 0)
    if "peak_memory_mib" in part:
        peak = total.setdefault("peak_memory_mib", dict(part["peak_memory_mib"]))
        peak["max"] = max(peak.get("max", 0), part["peak_memory_mib"]["max"])
    for k, v in part.get("outcomes", {}).items():
        total["outcomes"][k] = total["outcomes"].get(k, 0) + v
    for key in ("crashes", "notes"):
        by = {(c.get("signature") or c.get("note")): c for c in total[key]}
        for c in part.get(key, []):
            name = c.get("signature") or c.get("note")
            if name in by:
                by[name]["count"] += c["count"]
            else:
                total[key].append(c)
                by[name] = c
        total[key].sort(key=lambda c: -c["count"])
    total["native_stderr_cases"]["cases"] += part.get("native_stderr_cases", {}).get("cases", 0)
    total["warning_cases"] += part.get("warning_cases", 0)
    total["seconds"] = round(total["seconds"] + part.get("seconds", 0), 1)
    cs, pcs = total["case_seconds"], part.get("case_seconds", {})
    cs.update(sum=cs["sum"] + pcs.get("sum", 0), max=max(cs["max"], pcs.get("max", 0)),
              over_1s=cs["over_1s"] + pcs.get("over_1s", 0))  # fmt: skip
    total["complete"] = part.get("complete", False)
    total["error"] = part.get("error", "")
    return total


def _empty(name: str) -> dict[str, Any]:
    return {"target": name, "cases": 0, "outcomes": {}, "crashes": [], "notes": [], "complete": False, "error": "",
            "native_stderr_cases": {"cases": 0, "example": "", "output": ""}, "warning_cases": 0, "seconds": 0.0,
            "case_seconds": {"sum": 0.0, "max": 0.0, "over_1s": 0}}  # fmt: skip


def _run_all(args: argparse.Namespace) -> None:
    sys.path.insert(0, str(TESTS))
    import fuzz_cases as fc
    from common import report

    names = args.targets.split(",") if args.targets else list(fc.TARGETS)
    unknown = [n for n in names if n not in fc.TARGETS]
    if unknown:
        raise SystemExit(f"unknown target(s) {unknown}; valid: {', '.join(fc.TARGETS)}")
    fc.reference_files()  # fail early if the reference maps cannot be built
    tmp = Path(tempfile.mkdtemp(prefix="fuzz-"))
    pending: list[tuple[str, int]] = [(n, 0) for n in names]  # (target, restart)
    running: dict[str, tuple[subprocess.Popen[bytes], float, int]] = {}
    results: dict[str, dict[str, Any]] = {}
    kept_files = False
    t0 = time.perf_counter()

    def log(text: str) -> None:
        print(f"[{time.perf_counter() - t0:7.0f} s] {text}", flush=True)

    while pending or running:
        while pending and len(running) < args.jobs:
            name, restart = pending.pop(0)
            done = results[name]["cases"] if name in results else 0
            stem = tmp / f"{name}.{restart}"
            cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", name, "--result", f"{stem}.json",
                   "--examples", str(args.examples - done), "--seed", str(args.seed + 7919 * restart),
                   "--case-timeout", str(args.case_timeout), "--native-timeout", str(args.native_timeout),
                   "--memory-gib", str(args.memory_gib)]  # fmt: skip
            running[name] = (subprocess.Popen(cmd, cwd=tmp), time.perf_counter(), restart)
            log(
                f"start {name}"
                + (f" (restart {restart}, {args.examples - done} cases to go)" if restart else "")
            )
        time.sleep(0.5)
        for name, (proc, started, restart) in list(running.items()):
            timed_out = time.perf_counter() - started > args.worker_timeout
            if proc.poll() is None and not timed_out:
                continue
            if timed_out:
                proc.kill()
                proc.wait()
            del running[name]
            stem = tmp / f"{name}.{restart}"
            path = Path(f"{stem}.json")
            part = json.loads(path.read_text()) if path.exists() else _empty(name)
            total = _merge(results.get(name), part)
            results[name] = total
            dump = Path(f"{stem}.hang.txt").read_text() if Path(f"{stem}.hang.txt").exists() else ""
            last = Path(f"{stem}.last_case.txt").read_text() if Path(f"{stem}.last_case.txt").exists() else ""
            if proc.returncode == 0 and part.get("complete"):
                log(f"done  {name}: {total['cases']} cases {total['outcomes']}")
            elif "Timeout" in dump and restart < MAX_RESTARTS:
                _merge(total, {"cases": 1, "outcomes": {fc.HANG: 1}, "crashes": [_native_hang(dump, args.native_timeout, name, last)]})  # fmt: skip
                total.setdefault("native_hangs", []).append({"case": last, "stack": dump[-1500:]})
                log(f"hang  {name}: stuck in native code; restarting for the remaining cases")
                if total["cases"] < args.examples:
                    pending.insert(0, (name, restart + 1))
                else:
                    total["complete"] = True
            else:
                stderr = Path(f"{stem}.stderr.txt")
                total.setdefault("worker_died", []).append({
                    "returncode": proc.returncode,
                    "timed_out": timed_out,
                    "last_case": last,
                    "stderr_tail": stderr.read_bytes()[-1500:].decode(errors="replace") if stderr.exists() else "",
                })  # fmt: skip
                kept_files = True
                log(
                    f"DIED  {name}: returncode {proc.returncode} after {total['cases']} cases; files in {tmp}"
                )
    wall = time.perf_counter() - t0
    if not kept_files:
        shutil.rmtree(tmp, ignore_errors=True)
    for r in results.values():
        cs = r.pop("case_seconds")
        r["case_ms"] = {"mean": round(1e3 * cs["sum"] / max(1, r["cases"]), 2), "max": round(1e3 * cs["max"], 1),
                        "cases_over_1s": cs["over_1s"]}  # fmt: skip
        r["doc"], r["kind"] = fc.TARGETS[r["target"]].doc, fc.TARGETS[r["target"]].kind

    runs = [
        {"targets": names, "examples_per_target": args.examples, "seed": args.seed, "wall_s": round(wall, 1)}
    ]
    previous = json.loads(RESULTS_FILE.read_text()) if args.update and RESULTS_FILE.exists() else None
    if previous:  # keep the other targets of the last report, replace the ones run now
        kept = {r["target"]: r for r in previous["targets"] if r["target"] not in results}
        results = {**kept, **results}
        names = [n for n in fc.TARGETS if n in results]
        runs = previous.get("runs", []) + runs
    totals: Counter[str] = Counter()
    for r in results.values():
        totals.update(r.get("outcomes", {}))
    known = sorted({c["known_bug"] for r in results.values() for c in r.get("crashes", []) if c["known_bug"]})
    unmatched = [
        {"target": r["target"], **c}
        for r in results.values()
        for c in r.get("crashes", [])
        if not c["known_bug"]
    ]
    report(
        "fuzz",
        {
            "runs": runs,
            "jobs": args.jobs,
            "case_timeout_s": args.case_timeout,
            "native_timeout_s": args.native_timeout,
            "memory_limit_gib": args.memory_gib,
            "cases": sum(totals.values()),
            "totals": dict(totals),
            "known_bugs_hit": known,
            "unmatched_crashes": unmatched,
            "workers_died": [n for n, r in results.items() if "worker_died" in r],
            "targets": [results[n] for n in names],
        },
    )
    print(f"\n{'target':16} {'cases':>6} {'loaded':>7} {'clean':>7} {'crash':>6} {'hang':>5} {'viol':>5} "
          f"{'notes':>6} {'stderr':>6} {'ms/case':>8} {'s':>6} {'peakMiB':>8}")  # fmt: skip
    for n in names:
        r = results[n]
        o = r.get("outcomes", {})
        print(
            f"{n:16} {r.get('cases', 0):6} {o.get('loaded', 0):7} {o.get('clean', 0):7} {o.get('crash', 0):6} "
            f"{o.get('hang', 0):5} {o.get('violated', 0):5} {sum(x['count'] for x in r.get('notes', [])):6} "
            f"{r.get('native_stderr_cases', {}).get('cases', 0):6} {r.get('case_ms', {}).get('mean', 0):8} "
            f"{r.get('seconds', 0):6} {r.get('peak_memory_mib', {}).get('max', 0):8}"
            + ("  WORKER DIED" if "worker_died" in r else "")
        )
        for c in r.get("crashes", []):
            print(
                f"    {c['count']:5} {c['outcome']:8} {c['signature']}  [{c['known_bug'] or 'NEW'}]  {c['message'][:80]}"
            )
    print(f"\n{sum(totals.values())} cases; outcomes {dict(totals)}; known bugs hit: {known}")
    if unmatched:
        print(
            f"{len(unmatched)} crash signature(s) match no known bug: see unmatched_crashes in {RESULTS_FILE}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=int, default=10_000, help="cases per target")
    parser.add_argument("--targets", default="", help="comma-separated target names (default: all)")
    parser.add_argument("--jobs", type=int, default=2, help="targets fuzzed in parallel")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--case-timeout", type=float, default=20.0, help="a case running longer is a hang [s]"
    )
    parser.add_argument(
        "--native-timeout",
        type=float,
        default=90.0,
        help="a case stuck this long in native code ends its worker [s]",
    )
    parser.add_argument(
        "--worker-timeout", type=float, default=7200.0, help="a worker running longer is killed [s]"
    )
    parser.add_argument("--memory-gib", type=float, default=8.0, help="address-space limit of each worker")
    parser.add_argument(
        "--update", action="store_true", help="replace only the targets run now in the existing fuzz.json"
    )
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--result", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        _worker(args)
    else:
        _run_all(args)


if __name__ == "__main__":
    main()
