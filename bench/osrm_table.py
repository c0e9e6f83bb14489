"""Markdown tables of a results file from ``baseplace experiment osrm --results FILE``.

Usage: python bench/osrm_table.py bench/results/experiment_osrm.json
"""

from __future__ import annotations

import json
import sys


def _ms(v: list[float] | None) -> str:
    return "-" if v is None else f"{v[0]:.0f} ± {v[1]:.0f}"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def main(path: str) -> None:
    with open(path) as f:
        result = json.load(f)
    run = result.get("provenance") or result["run"]  # "run": files written before the one provenance writer
    print(f"`{run['command']}` at commit {run['commit']}, seed {result['seed']} ({result['seed_role']}), "
          f"{run['wall_time_s'] / 60:.1f} min\n")  # fmt: skip
    print("| scene | strategy | queries | N=1 | N=3 | N=10 | N=100 (paper) | on incline | t_RM [ms] | t_a [ms] | t_s [ms] "
          "| no IK / collision / exhausted | touched: support / obstacle / object / self |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in result["rows"]:
        at = r["success_rate_at"]
        paper = "" if r["paper_success_rate"] is None else f" ({r['paper_success_rate']})"
        fails = r["failures"]
        t = r["collisions_touching"]
        incline = "-" if r["on_inclined_plane"] is None else f"{r['on_inclined_plane']:.0f} %"
        print(f"| {r['scene']} | {r['strategy']} | {r['queries']} | {_pct(at['1'])} | {_pct(at['3'])} | {_pct(at['10'])} "
              f"| **{_pct(at['100'])}**{paper} | {incline} | {_ms(r['t_RM_ms'])} | {_ms(r['t_a_ms'])} | {_ms(r['t_s_ms'])} "
              f"| {fails.get('no_ik', 0)} / {fails.get('collision', 0)} / {fails.get('exhausted', 0)} "
              f"| {t.get('support', 0)} / {t.get('obstacle', 0)} / {t.get('grasped_object', 0)} / {t.get('self', 0)} |")  # fmt: skip
    seg = {r["scene"]: r["segmentation_ms"] for r in result["rows"]}
    print("\nsegmentation per scene [ms]: " + ", ".join(f"{k} {_ms(v)}" for k, v in seg.items()))
    grasps = {
        r["scene"]: (r["grasps"], r["planner_turned_down"], r["reachable_grasps"]) for r in result["rows"]
    }
    print("grasps (candidates / planner draws turned down / reachable): "
          + ", ".join(f"{k} {a}/{b}/{c}" for k, (a, b, c) in grasps.items()))  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1])
