"""The human-readable form of a report (what a command prints without ``--json``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from baseplace.jobs.inputs import DEFAULT_MAP_SAMPLES

# Below these a one-line hint follows the figure (the text form only): docs/maps.md and
# docs/placement.md say what the values mean and why these thresholds.
LOW_RECALL = 0.95
"""A map's recall below which it misses enough reachable poses that more samples are needed."""
LOW_PRECISION = 0.85
"""A map's precision below which many of the bases it proposes fail IK (slower queries)."""
LOW_ROBUSTNESS = 0.8
"""A placement's robustness below which one stop in five or more misses the grasp."""


def _robust(row: dict[str, Any]) -> str:
    r = row.get("robustness")
    return "" if r is None else f" robustness {r['rate']:.2f} [{r['ci95'][0]:.2f}, {r['ci95'][1]:.2f}]"


def _wrote(obj: dict[str, Any], *keys: str) -> list[str]:
    return [f"wrote {obj['outputs'][k]}" for k in keys if k in obj["outputs"]]


def _robustness_hint(rows: list[dict[str, Any]]) -> list[str]:
    low = [
        r["robustness"]["rate"]
        for r in rows
        if r.get("robustness") and r["robustness"]["rate"] < LOW_ROBUSTNESS
    ]
    if not low:
        return []
    return [f"hint: robustness {min(low):.2f} is low (below {LOW_ROBUSTNESS}): the grasp fails from "
            f"{1 - min(low):.0%} of the drawn base stops; --rank-by-robustness puts robust placements first, "
            f"--min-robustness {LOW_ROBUSTNESS} rejects the rest (docs/placement.md)"]  # fmt: skip


def _query_ms(o: dict[str, Any]) -> float:
    """The command's time without the map's build (first run) or load."""
    t = o["timings_ms"]
    return max(0.0, t["total"] - t.get("map_build", 0.0) - t.get("map", 0.0))


def _map_built(o: dict[str, Any]) -> list[str]:
    """A line where the default map was built now (first run): how long, and where the cache keeps it."""
    build = o["timings_ms"].get("map_build")
    if build is None:
        return []
    where = f", cached at {o['outputs']['map']}" if "map" in o["outputs"] else " (not cached)"
    return [f"built the default reachability map in {build / 1e3:.1f} s (first run only){where}"]


def _place(o: dict[str, Any]) -> list[str]:
    lines = [f"{len(o['placements'])} verified placement(s) in {o['tries']} tries ({o['strategy']}, "
             f"{_query_ms(o):.0f} ms)"]  # fmt: skip
    lines += [f"  x={r['x']:.3f} y={r['y']:.3f} z={r['z']:.3f} yaw={r['yaw']:.3f} region {r['region']} "
              f"reachability {r['reachability']:.3f}{_robust(r)}" for r in o["placements"]]  # fmt: skip
    return lines + _robustness_hint(o["placements"]) + _wrote(o, "png", "mcap") + _map_built(o)


def _candidates(o: dict[str, Any]) -> list[str]:
    rank = "robustness" if o["inputs"].get("rank") == "robustness" else "motion cost"
    lines = [f"{len(o['candidates'])} verified {o['method']} candidate(s), best first ({rank}):"]
    lines += [f"  x={r['x']:.3f} y={r['y']:.3f} yaw={r['yaw']:.3f} cost {r['motion_cost']:.2f} m{_robust(r)}"
              for r in o["candidates"]]  # fmt: skip
    return lines + _robustness_hint(o["candidates"]) + _wrote(o, "png", "mcap") + _map_built(o)


def _surface_map(o: dict[str, Any]) -> list[str]:
    head = (f"surface map of {len(o['polygon'])}-gon at {o['height']} m for {o['robot']['name']} arms "
            f"{'+'.join(o['arms'])} ({o['combine']}): {o['nonzero_poses']} poses with R_S > 0, max R_S "
            f"{o['max']:.2f}, built in {o['timings_ms']['build']:.1f} ms")  # fmt: skip
    return [head, f"wrote {o['outputs']['surface_map']} ({o['file_bytes'] / 1e3:.1f} kB)", *_wrote(o, "png")]


def _surface_samples(o: dict[str, Any]) -> list[str]:
    lines = [f"{'x':>7} {'y':>7} {'yaw':>7} {'R_S':>6} {'score':>6}"]
    return lines + [f"{p['x']:7.3f} {p['y']:7.3f} {p['yaw']:7.3f} {p['reachability']:6.3f} {p['score']:6.3f}"
                    for p in o["poses"]]  # fmt: skip


def _navigate(o: dict[str, Any]) -> list[str]:
    return [f"{o['planner']} path of {o['length']:.2f} m through regions {o['regions']} "
            f"in {o['timings_ms']['path']:.0f} ms, {len(o['poses'])} poses", *_wrote(o, "png", "mcap")]  # fmt: skip


def _segment(o: dict[str, Any]) -> list[str]:
    lines = [f"{len(o['regions'])} planar regions from {o['cloud']['points']} points at {o['resolution']:g} m "
             f"cells ({o['timings_ms']['total']:.0f} ms, {o['algorithm']})"]  # fmt: skip
    lines += [f"  region {r['id']}: tilt {r['tilt_deg']:.1f} deg, area {r['area_m2']:.2f} m^2, "
              f"centroid z {r['centroid'][2]:.3f} m" for r in o["regions"]]  # fmt: skip
    trav = sum(e["traversable"] for e in o["edges"])
    return [*lines, f"{len(o['edges'])} border edges, {trav} traversable", *_wrote(o, "png")]


def _demo(o: dict[str, Any]) -> list[str]:
    p, route, t = o["placement"], o["path"], o["timings_ms"]
    return [
        f"map {o['map']['path']} ({'built' if o['map']['built_now'] else 'cached'})",
        f"{o['regions']} planar regions; verified placement on region {p['region']} (tilt "
        f"{p['region_tilt_deg']:.1f} deg): x={p['x']:.2f} y={p['y']:.2f} z={p['z']:.2f} yaw={p['yaw']:.2f}",
        f"path from {o['inputs']['start']}: {route['length']:.2f} m through regions {route['regions']}",
        f"segmentation {t['segmentation']:.0f} ms, OSRM {t.get('osrm', 0):.0f} ms, query {t.get('query', 0):.0f} ms, "
        f"path {t['path']:.0f} ms, total {t['total'] / 1e3:.1f} s",
        f"wrote {o['outputs']['json']} and {o['outputs']['png']}",
    ]


def _build_map(o: dict[str, Any]) -> list[str]:
    if o.get("reused"):
        lines = [f"wrote {o['outputs']['map']}: not rebuilt, the same map was already built and cached at "
                 f"{o['cached_at']} ({o['cells_reached']} cells reached by {o['samples']:.3g} samples, built "
                 f"in {o['build_time_s']:.1f} s), {o['file_bytes'] / 1e6:.1f} MB"]  # fmt: skip
    else:
        lines = [f"wrote {o['outputs']['map']}: {o['cells_reached']} cells reached by {o['samples']:.3g} samples "
                 f"in {o['build_time_s']:.1f} s ({o['samples_per_s'] / 1e6:.2f} M samples/s), "
                 f"{o['file_bytes'] / 1e6:.1f} MB"]  # fmt: skip
    if o.get("cached_at") and not o.get("reused"):
        lines.append(f"also cached at {o['cached_at']} (place, reach and explain use it without --map)")
    if o.get("support"):
        sup, q = o["support"], o.get("quality") or {}
        fill = f", fill {sup['fill']}" if sup.get("fill") else ", no fill"
        line = f"support test: count {sup['count']}, threshold {sup['threshold']}{fill}"
        if q.get("ladder"):
            tried = "; ".join(f"{r['threshold']}/{r['fill']}: {r['recall']:.2%}" for r in q["ladder"])
            target = f"{q['target_recall']:.1%}"
            kept = (
                f"kept the first at >= {target}" if q["met"] else f"none reached {target}: kept the loosest"
            )
            line += f" (chosen on the map's own FK recall, threshold/fill {tried}; {kept})"
        lines.append(line)
    if o.get("quality"):
        q = o["quality"]
        lines.append(f"measured: recall {q['recall']:.2%} on {q['n_recall']} FK poses, precision "
                     f"{q['precision']:.1%} against IK on {q['n_precision']} poses (docs/maps.md)")  # fmt: skip
        if q["recall"] < LOW_RECALL:
            more = f"{max(4 * o['samples'], DEFAULT_MAP_SAMPLES):.0e}".replace("e+0", "e").replace("e+", "e")
            lines.append(f"hint: recall {q['recall']:.1%} is low (below {LOW_RECALL:.0%}): the map misses "
                         f"reachable poses; build with more samples (--samples {more})")  # fmt: skip
        if q["precision"] < LOW_PRECISION:
            lines.append(f"hint: precision {q['precision']:.1%} is low (below {LOW_PRECISION:.0%}): many poses "
                         "it calls reachable fail IK (more tries per placement); build with the support test's "
                         "threshold 0.8 or finer cells (--voxel-size 0.05, --orientation-resolution 0.4) and "
                         "more samples")  # fmt: skip
    return lines


def _robots(o: dict[str, Any]) -> list[str]:
    lines = []
    for r in o["robots"]:
        arms = ", ".join(
            f"{a} (TCP {s['tcp_frame']}, {len(s['joints'])} joints)" for a, s in r["arms"].items()
        )
        lines.append(f"{r['name']:<11} base {r['base_frame']}; arms {arms}")
    return [*lines, "custom robots: pass --robot path/to/robot.toml; check one with `baseplace robot check` "
            "(docs/robots.md)"]  # fmt: skip


def _robot_check(o: dict[str, Any]) -> list[str]:
    fp = o["footprint"]
    lines = [
        f"robot {o['name']}: URDF {o['urdf']}",
        f"base frame {o['base_frame']}; footprint "
        + (f"radius {fp['radius']} m" if "radius" in fp else f"polygon {fp['polygon']}")
        + (f"; meshes fixed to the base reach {fp['base_mesh_radius']} m from its origin"
           if "base_mesh_radius" in fp else ""),
    ]  # fmt: skip
    if o.get("mount") is not None:
        m = o["mount"]
        lines.append(f"arm mounted at xyz {m['xyz']} rpy {m['rpy']}, base body up to {m['base_height']} m")
    for name, arm in o["arms"].items():
        lines.append(f"arm {name!r}: TCP {arm['tcp_frame']}, approach axis {arm['approach']} "
                     f"(at the reference configuration: TCP at {arm['tcp_at_reference']}, approach "
                     f"{arm['approach_in_base_at_reference']} in {o['base_frame']})")  # fmt: skip
        lines += [
            f"  {j['name']:<24} {j['type']:<10} [{j['lower']:.4g}, {j['upper']:.4g}]" for j in arm["joints"]
        ]
    col = o["collision"]
    pairs = o["inputs"].get("pairs", False)
    lines.append(f"collision: {col['geometries']} geometries, {col['pairs']} active self-collision pairs "
                 f"({'SRDF ' + col['srdf'] if col['srdf'] else 'pruned as MoveIt does, no SRDF'})"
                 + ("" if pairs else "; --pairs lists them"))  # fmt: skip
    if pairs:
        lines += [f"  {a} - {b}" for a, b in col["pair_names"]]
    lines.append(f"wrote {o['outputs']['png']}")
    lines += [f"warning: {w}" for w in o["warnings"]] or ["no warnings"]
    if col.get("srdf_fix"):
        lines.append(
            "paste into the SRDF, inside <robot> (the touching pairs, then the other adjacent links, "
            "as MoveIt's setup assistant disables them):"
        )
        lines += [f"  {line}" for line in col["srdf_fix"]]
    return lines


def _occupancy(o: dict[str, Any]) -> list[str]:
    import numpy as np

    v = np.asarray(o["data"])
    return [f"{o['width']} x {o['height']} cells of {o['resolution']} m, origin {list(o['origin'])}: "
            f"{int((v == 0).sum())} free, {int((v == 100).sum())} occupied, {int((v < 0).sum())} unknown, "
            f"{int(((v > 0) & (v < 100)).sum())} in between"]  # fmt: skip


def _scene(o: dict[str, Any]) -> list[str]:
    return [f"wrote {o['outputs']['cloud']} ({o['points']} points) and {o['outputs']['truth']} "
            f"({o['planes']} {o['size_class']} planes, seed {o['seed']})"]  # fmt: skip


def _reach(o: dict[str, Any]) -> list[str]:
    return [f"{v:.6g}" for v in o["values"]] + _map_built(o)


def _explain(o: dict[str, Any]) -> list[str]:
    m, ik, b = o["map"], o["ik"], o["base"]
    lines = [o["verdict"]["summary"],
             f"  base x={b['x']:.3f} y={b['y']:.3f} z={b['z']:.3f} yaw={b['yaw']:.3f} region {b['region']}",
             f"  map value {m['value']:.3f} (cell {m['cell_value']:.3f}, support test {m['support']})",
             f"  IK {'solved' if ik['solved'] else 'failed'} from {ik['starts']} starts: "
             f"{ik['position_error']:.4f} m, {ik['rotation_error']:.4f} rad from the target"]  # fmt: skip
    lines += [f"  collision: link {c['link']} touched {c['touched']}" for c in o["collisions"]]
    mo = o["motion"]
    if mo["checked"]:
        lines.append(f"  reaching motion {'found' if mo['found'] else 'not found'}")
        lines += [f"  motion blocked: link {c['link']} touched {c['touched']}" for c in mo["contacts"]]
    return lines + _map_built(o)


def _point(o: dict[str, Any]) -> list[str]:
    target = o["object"]
    lines = [f"gesture {o['gesture']['name']}; {len(o['objects'])} object(s); selected object {o['selected']} at "
             f"x={target['position'][0]:.3f} y={target['position'][1]:.3f} z={target['position'][2]:.3f}, "
             f"size {' x '.join(f'{v:.3f}' for v in target['size'])} m"]  # fmt: skip
    if o["candidates"] is not None:
        lines.append(f"{len(o['candidates'])} verified candidate(s) to pick it up, best first:")
        lines += [f"  x={r['x']:.3f} y={r['y']:.3f} yaw={r['yaw']:.3f}" for r in o["candidates"]]
    return lines


RENDERERS: dict[str, Callable[[dict[str, Any]], list[str]]] = {
    "place": _place, "candidates": _candidates, "surface_map": _surface_map, "surface_samples": _surface_samples,
    "navigate": _navigate, "segment": _segment, "demo": _demo, "build_map": _build_map, "robots": _robots,
    "robot_check": _robot_check, "occupancy": _occupancy, "scene": _scene, "reach": _reach,
    "explain": _explain, "point": _point,
}  # fmt: skip


def report_text(obj: dict[str, Any]) -> str:
    """The lines a command prints for a successful report's JSON object."""
    return "\n".join(RENDERERS[obj["kind"]](obj))
