"""The docs' tables, printed as Markdown from the results files the commands wrote (never typed in).

Usage: python bench/results_tables.py segmentation|surface|table-grid|execution|platform [RESULTS.json ...]

segmentation: bench/results/experiment_segmentation.json (held-out) [+ _dev.json]
surface:      bench/results/surface_map.json
table-grid:   bench/results/experiment_table_grid.json (held-out) [+ dev files]
execution:    bench/results/execution_table_grid_heldout_v2.json [+ other runs]
platform:     bench/results/execution_platform_heldout.json [+ the dev run]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).parent / "results"


def _load(path: str | Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads(Path(path).read_text())
    return data


def _source(data: dict[str, Any]) -> str:
    p = data["provenance"]
    return (f"`{p['command']}` (commit {str(p['commit'])[:7]}{' + uncommitted changes' if p['dirty'] else ''}, "
            f"{p['split'] or 'custom'} run, seeds used {p.get('seeds_used')}, {p['wall_time_s']} s)")  # fmt: skip


def segmentation(paths: list[str]) -> None:
    """One table per noise model and file: per class and overall, both algorithms, and the seed's row."""
    for path in paths:
        data = _load(path)
        print(f"From {_source(data)}:\n")
        for noise, run in data["noise_models"].items():
            where = "height map (seed 000 VI's model)" if noise == "heightmap" else "dense cloud"
            print(f"Noise on the {where}, sigma {1000 * run['sigma_m']:.0f} mm, seed {run['seed']}:\n")
            print("| scenes | baseline: cells on true plane | baseline: mean normal error "
                  "| robust: cells on true plane | robust: mean normal error |")  # fmt: skip
            print("|---|---|---|---|---|")
            by = {(r["size_class"], r["planes"], r["algorithm"]): r for r in run["rows"]}
            for size, planes in dict.fromkeys((r["size_class"], r["planes"]) for r in run["rows"]):
                b, r = by[(size, planes, "baseline")], by[(size, planes, "robust")]
                print(f"| {size}, {planes} planes | {100 * b['cell_accuracy']:.2f} % | {b['mean_normal_error_deg']:.2f}° "
                      f"| {100 * r['cell_accuracy']:.2f} % | {r['mean_normal_error_deg']:.3f}° |")  # fmt: skip
            b, r = run["overall"]["baseline"], run["overall"]["robust"]
            print(f"| **all {r['scenes']} scenes** | **{100 * b['cell_accuracy']:.2f} %** | **{b['mean_normal_error_deg']:.2f}°** "
                  f"| **{100 * r['cell_accuracy']:.2f} %** | **{r['mean_normal_error_deg']:.3f}°** "
                  f"(max {r['max_normal_error_deg']:.2f}°) |")  # fmt: skip
            paper = data["paper"]
            print(
                f"| seed 000 (robust) | | | {100 * paper['cell_accuracy']:.1f} % | {paper['mean_normal_error_deg']}° |\n"
            )


def surface(paths: list[str]) -> None:
    """Validation time and agreement (raw and calibrated) of the surface map."""
    data = _load(paths[0] if paths else RESULTS / "surface_map.json")
    v, g, b = data["validation"], data["ground_truth"], data["build"]
    print(f"From {_source(data)}:\n")
    print("| | baseplace | seed 002 |\n|---|---|---|")
    print(f"| build, no validation | {1e3 * b['median_s']:.0f} ms median of {b['repeats']} | |")
    print(f"| per-pose validation (IK + collision), median over {v['timed_kept_poses']} kept poses "
          f"| {v['seconds_per_kept_pose_median']:.2f} s per pose | |")  # fmt: skip
    print(f"| build with every kept pose validated ({v['kept_poses']:,} poses) "
          f"| {v['validated_map_build_h_estimate']:.1f} h (estimate: poses x median) | about 2.5 days (20 M poses) |")  # fmt: skip
    print()
    print(
        "| poses | MAE | MAE, R_S > 0 | bias (map - IK), R_S > 0 | mean IK share, R_S > 0 | overestimated |"
    )
    print("|---|---|---|---|---|---|")
    rows = [("dev, raw R_S", g["dev_raw"]), ("held-out, raw R_S", g["held_out_raw"]),
            (f"held-out, calibrated (R_P x {g['calibration']['scale']:.3f}, fit on dev)", g["held_out_calibrated"])]  # fmt: skip
    for name, a in rows:
        print(f"| {name} ({a['poses']}, {a['nonzero_rs']} with R_S > 0) | {a['mae']:.3f} | {a['mae_nonzero_rs']:.3f} "
              f"| {a['bias_nonzero_rs']:+.3f} | {a['mean_truth_nonzero_rs']:.3f} "
              f"| {a['overestimated_nonzero_rs']}/{a['nonzero_rs']} |")  # fmt: skip


def table_grid(paths: list[str]) -> None:
    """Success per method (and row 3) for each file, with the seed's numbers."""
    print(
        "| run | radial | IRM-verified | fixed pose | any placement works | surface margin | IRM top-down depth |"
    )
    print("|---|---|---|---|---|---|---|")
    for path in paths:
        data = _load(path)
        t = data["totals"]
        n = t["radial"]["success"] + t["radial"]["failure"]

        def cell(m: str, t: dict[str, Any] = t, n: int = n) -> str:
            return f"{t[m]['success']}/{n} ({t[m]['rate']:.1f} %)"

        feasible = cell("feasible") if "feasible" in t else "-"
        p = data["provenance"]
        print(f"| {p['split']} seed {p['seeds_used']} | {cell('radial')} | {cell('irm')} | {cell('baseline')} "
              f"| {feasible} | {data['radial_settings']['surface_margin']} | {data['settings']['method_top_below']} |")  # fmt: skip
    print("| seed 004 (HSR) | 49/60 (81.7 %) proposed | | 24/60 (40 %) | | | |")
    for path in paths:
        print(f"\n{Path(path).name}: {_source(_load(path))}")


def execution(paths: list[str]) -> None:
    """Per file: successful draws per method with the Wilson interval, and the outcome counts."""
    names = {"baseline": "seed 004 fixed pose", "radial": "seed 004 radial (Alg. 1-2)",
             "default": "baseplace default (motion check)", "robust": "baseplace, ranked by robustness"}  # fmt: skip
    kinds = ("no_placement", "no_grasp", "no_motion", "motion_collision")
    for path in paths:
        data = _load(path)
        pr = data["protocol"]
        print(f"Protocol v{pr.get('version', 1)}, {pr['split']} seeds {pr['seeds']}, {pr['cells']} cells, "
              f"{pr['draws']} draws each; from {_source(data)}:\n")  # fmt: skip
        print("| method | success | 95 % interval | " + " | ".join(kinds) + " | mean planning [s] |")
        print("|---|---|---|" + "---|" * len(kinds) + "---|")
        for m, row in data["summary"].items():
            low, high = row.get("ci95", [None, None])
            ci = f"{100 * low:.0f}-{100 * high:.0f} %" if low is not None else "-"
            counts = " | ".join(str(row["outcomes"].get(k, 0)) for k in kinds)
            print(f"| {names.get(m, m)} | {row['success']}/{row['draws']} ({100 * row['rate']:.1f} %) | {ci} "
                  f"| {counts} | {row['mean_plan_s']} |")  # fmt: skip
        print()


def platform(paths: list[str]) -> None:
    """Per file: seed 000's platform scenes executed, per method (all classes, then per class)."""
    from baseplace.placement.robustness import wilson_interval

    names = {"TO": "seed 000 TO", "MR": "seed 000 MR", "MRTO": "seed 000 MRTO",
             "default": "baseplace default (MR + motion check)", "robust": "baseplace, ranked by robustness"}  # fmt: skip
    kinds = ("no_placement", "off_region", "no_grasp", "no_motion", "motion_collision")
    for path in paths:
        data = _load(path)
        pr = data["protocol"]
        print(f"{pr['split']} seeds {pr['seeds']}, classes {pr['classes']}, {pr['scenes_per_class']} scenes per "
              f"class, {pr['queries_per_scene']} queries per scene ({data['queries']} queries), {pr['draws']} draws "
              f"each; from {_source(data)}:\n")  # fmt: skip
        print("| method | scenes | success | 95 % interval | success where placed | " + " | ".join(kinds)
              + " | ok at the chosen pose | mean planning [s] |")  # fmt: skip
        print("|---|---|---|---|---|" + "---|" * len(kinds) + "---|---|")
        groups = [("all", data["trials"])] + [
            (" ".join(map(str, c)), [t for t in data["trials"] if t["class"] == c]) for c in pr["classes"]
        ]
        for m in data["summary"]:
            for label, trials in groups:
                out = [o for t in trials for o in t["methods"][m]["outcomes"]]
                ok, n = out.count("ok"), len(out)
                placed = n - out.count("no_placement")
                low, high = wilson_interval(ok, n)
                nominal_ok = sum(t["methods"][m].get("at_nominal") == "ok" for t in trials)
                with_pose = sum(t["methods"][m]["pose"] is not None for t in trials)
                recorded = any("at_nominal" in t["methods"][m] for t in trials)
                nominal = f"{nominal_ok}/{with_pose}" if recorded else "-"
                counts = " | ".join(str(out.count(k)) for k in kinds)
                rate = f"{ok}/{n} ({100 * ok / n:.1f} %)" if n else "-"
                where = f"{ok}/{placed}" if placed else "-"
                plan = sum(t["methods"][m]["plan_s"] for t in trials) / len(trials) if trials else 0.0
                print(f"| {names.get(m, m)} | {label} | {rate} | {100 * low:.0f}-{100 * high:.0f} % | {where} | "
                      f"{counts} | {nominal} | {plan:.2f} |")  # fmt: skip
        print()


def main() -> None:
    kind, paths = sys.argv[1], sys.argv[2:]
    tables = {
        "segmentation": segmentation,
        "surface": surface,
        "table-grid": table_grid,
        "execution": execution,
        "platform": platform,
    }
    tables[kind](paths)


if __name__ == "__main__":
    main()
