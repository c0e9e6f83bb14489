"""Where one collision check at a new base pose goes: the robustness score's draws (issue 25; development only).

The robustness score (:class:`~baseplace.placement.robustness.RobustnessEstimator`) checks each
error draw's IK configuration at the draw's own base pose, so every check meets a base pose the
state filter has not seen. On ``bench_warm_place.py``'s scenes (development seeds, its side grasp)
this takes each scene's first placement of a warm ``place`` query, draws its 64 base poses and IK
configurations as the score does, and times per draw (best of ``--repeat`` passes, one thread):

* ``check``: ``Environment.colliding_arm`` at the draw (the static-geometry answer not kept);
* ``static``: the filter's per-pose setup, the geometries no arm joint moves against the scene
  (sphere centres placed, then each scene part's ``_Part.uncertified``, one Python call each);
* ``kernel``: the compiled call for the arm's geometries and the self pairs, one state;
* ``place_scene``: placing the scene geometries for the pose (only when coal is asked);
* ``ik``: the draws' batched IK (as the score calls it);
* ``static_batched``: a prototype, not the product: the static geometries of all draws at once
  (their centres do not depend on the arm's joints), one compiled test per scene part; it must
  leave the same pairs to coal as ``static`` (checked).

Also how many pairs and states the draws hand to coal. Usage: python bench/profile_pose_check.py
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

import baseplace.world.state_filter as sf
from baseplace.geometry.poses import invert_transforms
from baseplace.placement.pipeline import PlaceSettings, place, scene_checks, with_floor
from baseplace.placement.robustness import RobustnessEstimator, perturbed
from baseplace.placement.scene_cache import SceneCache
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from baseplace.world.point_index import _clear
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.table_grid import TableGridSettings
from bench_warm_place import CELLS, GRASP, SEEDS
from common import report


def best_ms(fn: Callable[[], object], repeat: int, n: int) -> float:
    """Best of ``repeat`` runs of ``fn``, per one of its ``n`` items [ms]."""
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return float(best / n * 1e3)


def static_each(f: sf.StateFilter, Q: np.ndarray, poses: np.ndarray) -> list[list[int]]:
    """Per draw, the static pairs the filter leaves to coal, as its first_colliding finds them."""
    out = []
    for q, T in zip(Q, poses, strict=True):
        _ = sf._transformed(f.centres(q), T @ f._T_base_armbase, f._world)
        out.append(sorted(int(p) for part in f._static_parts for p in part.uncertified(f._world)))
    return out


def static_batched(f: sf.StateFilter, Q: np.ndarray, poses: np.ndarray) -> list[list[int]]:
    """The same for all draws at once (prototype): static centres placed by each pose, one test per part."""
    T = poses @ f._T_base_armbase
    c = f.centres(Q[0])  # a static geometry's centre does not depend on the arm's joints
    W = np.einsum("sij,gj->sgi", T[:, :3, :3], c) + T[:, None, :3, 3]
    S = len(poses)
    left: list[set[int]] = [set() for _ in range(S)]
    for part in f._static_parts:
        if len(part.robot_a) == 0:
            continue
        C = np.ascontiguousarray(W[:, part.robot_a].reshape(-1, 3))
        free, buf = np.ones(len(C), dtype=bool), np.empty(len(C), dtype=np.bool_)
        for arrays, reach in part._arrays:
            _clear(buf, C, np.tile(reach, S), *arrays)
            free &= buf
        if part.planes is not None:
            free = np.max(C @ part.planes[:, :3].T + part.planes[:, 3], axis=1) > np.tile(part.reach, S)
        elif not part._arrays and part.sphere is not None:
            free = np.linalg.norm(C - part.sphere[0], axis=1) > np.tile(part.reach, S) + part.sphere[1]
        for s, k in zip(*np.nonzero(~free.reshape(S, -1)), strict=True):
            left[s].add(int(part.pair_a[k]))
    return [sorted(x) for x in left]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--name", default="pose_check")
    args = parser.parse_args()
    robot = Robot("tiago")
    rmap = resolve_map(robot, None).rmap
    arm = robot.arm(rmap.info.arm)
    s = TableGridSettings()
    rows = []
    for seed in SEEDS:
        for cell in CELLS:
            _, p_est, seen = trial_scene(seed, cell, s)
            points = with_floor(seen, 0.0)
            cache = SceneCache(points)
            target = s.grasps(p_est)[GRASP][None]
            found = place(robot, rmap, points, target, PlaceSettings(), np.random.default_rng(1), cache=cache,
                          grasped="auto").placements  # fmt: skip
            if not found:
                continue
            p = found[0]
            env = scene_checks(robot, arm.name, points, cache.terrain(None), target, PlaceSettings(), "auto",
                               cache).verifier.environment  # fmt: skip
            est = RobustnessEstimator(arm, env, target)
            poses = perturbed(p.T_world_base, est.offsets)
            T_tcp = invert_transforms(poses) @ target[0]
            q, ok = est._ik.solve_batch(T_tcp, np.random.default_rng(2), p.joints[0])
            Q, P = q[ok], poses[ok]
            f = env.state_filter(arm)
            robot_args, scene_args = f._kernel_args
            out = np.empty((1, len(f._scene_rows) + len(f._self_pairs)), dtype=np.bool_)

            def check(f=f, env=env, Q=Q, P=P) -> None:
                for qi, T in zip(Q, P, strict=True):
                    f._static_key = None  # as a new pose
                    env.colliding_arm(arm, qi, T)

            def kernel(f=f, Q=Q, P=P, robot_args=robot_args, scene_args=scene_args, out=out) -> None:
                for qi, T in zip(Q, P, strict=True):
                    sf._uncertified_states(qi[None], *robot_args, T @ f._T_base_armbase, *scene_args, 0, out)

            def place_scene(env=env, P=P) -> None:
                for T in P:
                    env._placed = None
                    env._place_obstacles(T)

            pairs0, states0 = f.coal_pairs, f.coal_states
            check()
            coal = (f.coal_pairs - pairs0, f.coal_states - states0)
            same = static_each(f, Q, P) == static_batched(f, Q, P)
            n = len(Q)
            row = {
                "seed": seed, "cell": list(cell), "draws_checked": n, "coal_pairs": coal[0], "coal_states": coal[1],
                "check_ms": best_ms(check, args.repeat, n),
                "static_ms": best_ms(lambda f=f, Q=Q, P=P: static_each(f, Q, P), args.repeat, n),
                "kernel_ms": best_ms(kernel, args.repeat, n),
                "place_scene_ms": best_ms(place_scene, args.repeat, n),
                "ik_ms": best_ms(lambda e=est, T=T_tcp, p=p: e._ik.solve_batch(T, np.random.default_rng(2),
                                                                                 p.joints[0]), args.repeat, len(poses)),
                "static_batched_ms": best_ms(lambda f=f, Q=Q, P=P: static_batched(f, Q, P), args.repeat, n),
                "static_batched_same": same,
            }  # fmt: skip
            print({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
            rows.append(row)
    keys = ("check_ms", "static_ms", "kernel_ms", "place_scene_ms", "ik_ms", "static_batched_ms")
    medians = {k: float(np.median([r[k] for r in rows])) for k in keys}
    print(medians)
    report(args.name, {"medians": medians, "rows": rows})


if __name__ == "__main__":
    main()
