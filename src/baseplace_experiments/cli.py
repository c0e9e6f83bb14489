"""The ``baseplace experiment ...`` commands: the papers' experiments, registered into ``baseplace``.

:func:`add_experiment_commands` is the one call the ``baseplace`` parser makes; everything else
here (argument checks, progress, tables, results files) belongs to the experiments, not to the
library's command line.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from baseplace.argtypes import nonneg_int
from baseplace.errors import InputError
from baseplace.jobs.inputs import PLOT_SUFFIXES, out_path
from baseplace.status import ProgressBars


def _int_list(text: str) -> list[int]:
    """Parse "1,2,3" into [1, 2, 3]."""
    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of integers: {text!r}") from None


def _cell(value: Any, fmt: str, suffix: str = "") -> str:
    """A table cell: ``value`` formatted with ``fmt`` and ``suffix``, or "-" when it is None."""
    return "-" if value is None else format(value, fmt) + suffix


def _emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    sys.stdout.write(json.dumps(obj) + "\n" if args.json else text.rstrip("\n") + "\n")


def _bars(args: argparse.Namespace) -> ProgressBars:
    """Progress bars on stderr, none with --json."""
    return ProgressBars(enabled=not args.json)


def _default_map(args: argparse.Namespace, robot: Any, arm: str | None = None) -> Any:
    """The robot's cached default map, built on first use (tens of seconds) behind a progress bar."""
    from baseplace.reachability.cache import resolve_map

    with _bars(args) as bars:
        return resolve_map(robot, None, arm, bars).rmap


def _results_path(path: str | None) -> Path | None:
    """A results file to write (--results), checked before any work."""
    return out_path(path, "--results", (".json",))


def _write_results(
    path: Path | None, result: dict[str, Any], clock: Any, lines: list[str], **provenance: Any
) -> dict[str, Any]:
    """``result`` with its provenance (:mod:`baseplace_experiments.results`, the one writer).

    Written whole to the --results file when one was given (and said so in ``lines``).
    """
    from baseplace_experiments import results

    if path is None:
        return {**result, "provenance": results.provenance(clock, **provenance)}
    lines.append(f"wrote {path}")
    return results.write_results(path, result, clock, **provenance)


def cmd_experiment_segmentation(args: argparse.Namespace) -> int:
    """Segmentation accuracy of both algorithms on generated scenes, per noise model."""
    from baseplace_experiments import segmentation_eval
    from baseplace_experiments.results import RunClock, fixed_protocol
    from baseplace_experiments.segmentation_eval import (
        NOISE_MODELS,
        PAPER,
        SEEDS,
        run_segmentation_experiment,
    )

    clock = RunClock()
    if args.scenes < 1:
        raise InputError(f"--scenes must be at least 1, got {args.scenes}")
    noises = [n.strip() for n in args.noise.split(",") if n.strip()]
    for n in noises:
        if n not in NOISE_MODELS:
            raise InputError(f"unknown --noise {n!r}; valid: {', '.join(NOISE_MODELS)}")
    seed = args.seed if args.seed is not None else SEEDS.seeds(args.split)[0]
    split = args.split if args.seed is None or args.seed in SEEDS.seeds(args.split) else None
    results = _results_path(args.results)
    protocol_file = fixed_protocol(segmentation_eval.PROTOCOL_FILE, split)
    with _bars(args) as bars:
        bar = bars.counter("segmentation experiment", args.scenes * 6 * len(noises), "scenes")
        runs = {n: run_segmentation_experiment(args.scenes, seed, progress=bar, noise=n) for n in noises}
    result: dict[str, Any] = {"experiment": "segmentation", "paper": PAPER, "noise_models": runs}
    lines = []
    for noise, run in runs.items():
        lines.append(f"noise on the {'height map' if noise == 'heightmap' else 'cloud'} (sigma {run['sigma_m']} m), "
                     f"seed {seed}")  # fmt: skip
        lines.append(
            f"{'class':<7} {'planes':>6} {'algorithm':<9} {'cells ok':>9} {'normal err':>11} {'time':>8}"
        )
        for r in run["rows"]:
            lines.append(f"{r['size_class']:<7} {r['planes']:>6} {r['algorithm']:<9} {100 * r['cell_accuracy']:>8.2f}% "
                         f"{r['mean_normal_error_deg']:>9.3f}° {1e3 * r['median_seconds']:>6.0f}ms")  # fmt: skip
        for alg, o in run["overall"].items():
            lines.append(f"overall {alg}: {100 * o['cell_accuracy']:.2f}% cells, {o['mean_normal_error_deg']:.3f}° "
                         f"mean normal error, {o['missed_planes']} planes missed ({o['scenes']} scenes)")  # fmt: skip
    lines.append(f"Birr et al. VI: {100 * PAPER['cell_accuracy']:.1f}% cells, {PAPER['mean_normal_error_deg']}° "
                 "(noise on the height map)")  # fmt: skip
    result = _write_results(results, result, clock, lines, seeds=SEEDS, split=split, used_seeds=[seed],
                            protocol=(segmentation_eval.__doc__ or "").strip(), protocol_file=protocol_file)  # fmt: skip
    _emit(args, result, "\n".join(lines))
    return 0


def cmd_experiment_navigation(args: argparse.Namespace) -> int:
    """RRTConnect vs the region-graph planner on generated multi-level scenes."""
    from baseplace_experiments.navigation_experiment import CLASSES, run_navigation_experiment
    from baseplace_experiments.results import RunClock

    clock = RunClock()
    if args.scenes < 1 or args.pairs < 1:
        raise InputError(f"--scenes and --pairs must be >= 1, got {args.scenes} and {args.pairs}")
    results = _results_path(args.results)
    with _bars(args) as bars:
        bar = bars.counter("navigation experiment", args.scenes * len(CLASSES), "scenes")
        result = run_navigation_experiment(args.scenes, args.pairs, args.seed, progress=bar)
    lines = [f"{'scene':<16} {'planner':<8} {'pairs':>5} {'success':>8} {'false':>5} {'length m':>8} "
             f"{'time ms':>8} {'steps':>5}"]  # fmt: skip
    for r in result["rows"]:
        ok, length = _cell(r["success_rate"], ".1f", "%"), _cell(r["mean_length_m"], ".2f")
        ms = _cell(r["median_time_ms"], ".0f")
        lines.append(f"{r['scene']:<16} {r['planner']:<8} {r['pairs']:>5} {ok:>8} {r['paths_to_unreachable_goals']:>5} "
                     f"{length:>8} {ms:>8} {r['paths_crossing_a_step']:>5}")  # fmt: skip
    result = _write_results(results, result, clock, lines, used_seeds=[args.seed])
    _emit(args, result, "\n".join(lines))
    return 0


def cmd_experiment_inspect_table(args: argparse.Namespace) -> int:
    """Hertle and Nebel's inspect-every-object task (IV-B): predefined vs sampled poses with a PDDL planner."""
    from baseplace.placement.surface_map import build_surface_map
    from baseplace.robots.model import Robot
    from baseplace_experiments.inspect_task import INSPECT_TABLE, run_inspect_experiment
    from baseplace_experiments.results import RunClock

    clock = RunClock()
    counts = args.objects
    if args.runs < 1 or min(counts) < 1 or max(counts) > 8:
        raise InputError(f"need --runs >= 1 and object counts from 1 to 8, got {args.runs} and {counts}")
    results = _results_path(args.results)
    robot = Robot("pr2")
    rmaps = {arm: _default_map(args, robot, arm) for arm in ("left", "right")}
    smap = build_surface_map(robot, rmaps, *INSPECT_TABLE, combine="any")
    with _bars(args) as bars:
        bar = bars.counter("inspect-table experiment", 5 * len(counts) * args.runs, "runs")
        result = run_inspect_experiment(robot, rmaps, smap, tuple(counts), args.runs, args.seed, progress=bar)
    lines = [f"{'objects':>7} {'poses':<10} {'unsolved':>8} {'T min':>6} {'moves':>6} {'other':>6} "
             f"{'replans':>7} {'plan s':>7}"]  # fmt: skip
    for r in result["summary"]:
        cells = [_cell(r[key], ".1f") for key in ("exec_min", "moves", "other_actions", "replans", "plan_s")]
        lines.append(f"{r['objects']:>7} {r['config']:<10} {r['unsolved']:>5}/{r['runs']:<2} {cells[0]:>6} "
                     f"{cells[1]:>6} {cells[2]:>6} {cells[3]:>7} {cells[4]:>7}")  # fmt: skip
    result = _write_results(results, result, clock, lines, used_seeds=[args.seed])
    _emit(args, result, "\n".join(lines))
    return 0


def cmd_experiment_table_grid(args: argparse.Namespace) -> int:
    """Saini et al.'s table-grid experiment (section 4): fixed pose vs radial vs IRM-verified placements."""
    from baseplace.reachability.storage import load_map
    from baseplace.robots.model import Robot
    from baseplace_experiments import table_grid
    from baseplace_experiments.results import RunClock, fixed_protocol

    clock = RunClock()
    if args.trials < 1:
        raise InputError(f"--trials must be >= 1, got {args.trials}")
    for name, value in (("--surface-margin", args.surface_margin), ("--top-below", args.top_below)):
        if value is not None and not (math.isfinite(value) and 0.0 <= value <= 0.1):
            raise InputError(f"{name} must be between 0 and 0.1 m, got {value}")
    out = out_path(args.out, "--out", PLOT_SUFFIXES)
    results = _results_path(args.results)
    seeds = table_grid.SEEDS
    seed = args.seed if args.seed is not None else seeds.seeds(args.split)[0]
    split = args.split if args.seed is None or args.seed in seeds.seeds(args.split) else None
    protocol_file = fixed_protocol(table_grid.PROTOCOL_FILE, split)
    robot = Robot(args.robot)
    rmap = load_map(args.map, robot) if args.map else _default_map(args, robot)
    settings = table_grid.TableGridSettings()
    if args.top_below is not None:
        settings = table_grid.TableGridSettings(method_top_below=args.top_below)
    radial = table_grid.radial_settings(robot, rmap, settings, args.surface_margin)
    with _bars(args) as bars:
        bar = bars.counter("table-grid experiment", 12 * args.trials, "trials")
        result = table_grid.run_table_grid(robot, rmap, args.trials, seed, progress=bar,
                                           settings=settings, radial=radial, feasible=not args.no_feasible)  # fmt: skip
    if out is not None:
        from baseplace.viz.table_grid import plot_table_grid

        plot_table_grid(result, out)
        result["png"] = str(out)
    lines = [
        f"{'cell':<7} {'radial':>7} {'irm':>7} {'baseline':>9} {'paper prop.':>11} {'paper base':>10} {'feasible':>8}"
    ]
    for cell in result["cells"]:
        t, p = cell["table1"], cell["paper"]

        def sf(row: Any) -> str:
            return f"{row[0]}/{row[1]}" if row is not None else "-"

        lines.append(f"{tuple(cell['cell'])!s:<7} {sf(t.get('radial')):>7} {sf(t.get('irm')):>7} "
                     f"{sf(t.get('baseline')):>9} {sf(p.get('proposed')):>11} {sf(p.get('baseline')):>10} "
                     f"{cell.get('feasible', '-')!s:>8}")  # fmt: skip
    totals = result["totals"]
    lines.append("success rate: " + ", ".join(f"{m} {totals[m]['rate']:.1f}%" for m in ("radial", "irm", "baseline"))
                 + " (Saini et al. with an HSR: proposed 81.7%, baseline 40%)")  # fmt: skip
    result = _write_results(results, result, clock, lines, seeds=seeds, split=split, used_seeds=[seed],
                            protocol=(table_grid.__doc__ or "").strip(), protocol_file=protocol_file)  # fmt: skip
    _emit(args, result, "\n".join(lines))
    return 0


def cmd_experiment_osrm(args: argparse.Namespace) -> int:
    """Birr et al.'s Tables I and II on generated scenes (protocol: baseplace_experiments.osrm_experiment)."""
    from baseplace.reachability.storage import load_map
    from baseplace.robots.model import Robot
    from baseplace_experiments import osrm_experiment
    from baseplace_experiments.osrm_experiment import (
        SCENE_CLASSES,
        SEEDS,
        ExperimentSettings,
        run_osrm_experiment,
    )
    from baseplace_experiments.results import RunClock, fixed_protocol

    clock = RunClock()
    if args.protocol in (2, 3):
        return _experiment_osrm_v2(args, clock)
    if args.scenes is None:
        args.scenes = 10
    if args.grasps is None:
        args.grasps = 50
    if args.scenes < 1 or args.grasps < 1:
        raise InputError(f"--scenes and --grasps must be >= 1, got {args.scenes} and {args.grasps}")
    out, results_path = out_path(args.out, "--out", PLOT_SUFFIXES), _results_path(args.results)
    seed = SEEDS.dev[0] if args.dev else args.seed
    split = "held-out" if seed in SEEDS.held_out else "dev" if seed in SEEDS.dev else None
    protocol_file = fixed_protocol(osrm_experiment.PROTOCOL_FILE, split)
    robot = Robot(args.robot)
    rmap = load_map(args.map, robot) if args.map else _default_map(args, robot)
    classes = SCENE_CLASSES if not args.flat_only else SCENE_CLASSES[:1]
    settings = ExperimentSettings(grasps_per_scene=args.grasps, seed=seed, tries=args.tries)
    with _bars(args) as bars:
        bar = bars.counter("osrm experiment", args.scenes * len(classes), "scenes")
        if args.scheduler is None:
            result = run_osrm_experiment(robot, rmap, args.scenes, settings, classes, bar)
        else:
            from baseplace.reachability.distributed import connect

            with connect(args.scheduler) as client:
                result = run_osrm_experiment(
                    robot, rmap, args.scenes, settings, classes, bar, client, args.robot
                )
    if out is not None:
        from baseplace.viz.experiments import plot_failure_rates

        plot_failure_rates(result["rows"], out)
        result["png"] = str(out)
    lines = [
        f"{'scene':<16} {'strategy':<8} {'queries':>7} {'N=1':>6} {'N=3':>6} {'N=10':>6} {'N=100':>6} {'paper':>6} "
        f"{'incline':>7} {'t_RM ms':>9} {'t_a ms':>10} {'t_s ms':>10}"
    ]
    for r in result["rows"]:

        def f(v: Any) -> str:
            return "-" if v is None else f"{v[0]:.0f}±{v[1]:.0f}"

        at = [_cell(r["success_rate_at"][b], ".1f") for b in ("1", "3", "10", "100")]
        paper, incline = _cell(r["paper_success_rate"], ".1f"), _cell(r["on_inclined_plane"], ".0f", "%")
        lines.append(f"{r['scene']:<16} {r['strategy']:<8} {r['queries']:>7} {at[0]:>6} {at[1]:>6} {at[2]:>6} "
                     f"{at[3]:>6} {paper:>6} {incline:>7} {f(r['t_RM_ms']):>9} {f(r['t_a_ms']):>10} {f(r['t_s_ms']):>10}")  # fmt: skip
    lines.append(f"seed {seed} ({result['seed_role']}), {clock.seconds:.0f} s")
    result = _write_results(results_path, result, clock, lines, seeds=SEEDS, split=split, used_seeds=[seed],
                            protocol=(osrm_experiment.__doc__ or "").strip(), protocol_file=protocol_file)  # fmt: skip
    _emit(args, result, "\n".join(lines))
    return 0


def _experiment_osrm_v2(args: argparse.Namespace, clock: Any) -> int:
    """Protocol v2 or v3 of Tables I and II (docs/protocols/osrm_v2.md, osrm_v3.md): seeds, intervals, allowed grasps.

    v3 is v2 with the method's collision model from the clean cloud, its own seeds and v2's rows beside.
    """
    from baseplace.reachability.storage import load_map
    from baseplace.robots.model import Robot
    from baseplace_experiments import osrm_v2, osrm_v3
    from baseplace_experiments.osrm_experiment import SCENE_CLASSES
    from baseplace_experiments.results import fixed_protocol

    v3 = args.protocol == 3
    protocol: Any = osrm_v3 if v3 else osrm_v2

    scenes = osrm_v2.SCENES if args.scenes is None else args.scenes
    grasps = osrm_v2.GRASPS if args.grasps is None else args.grasps
    if args.seeds is not None:
        seeds = list(args.seeds)
        if set(seeds) & set(protocol.SEEDS.held_out) and seeds != list(protocol.SEEDS.held_out):
            raise InputError(
                f"held-out seeds {list(protocol.SEEDS.held_out)} run only all together: use --split held-out"
            )
        split = (
            "held-out"
            if seeds == list(protocol.SEEDS.held_out)
            else "dev"
            if seeds == list(protocol.SEEDS.dev)
            else None
        )
    else:
        split = args.split or "dev"
        seeds = list(protocol.SEEDS.seeds(split))
    if split == "held-out":
        protocol.held_out_settings_check(scenes, grasps, args.tries)
        if args.flat_only:
            raise InputError(f"a held-out protocol-v{args.protocol} run covers every class: drop --flat-only")
    results_path = _results_path(args.results)
    before = None
    if args.beside is not None:
        try:
            before = json.loads(Path(args.beside).read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"--beside {args.beside}: not a readable results file ({exc})") from None
        if v3:
            osrm_v3.beside_check(before)
    protocol_file = fixed_protocol(protocol.PROTOCOL_FILE, split)
    robot = Robot(args.robot)
    rmap = load_map(args.map, robot) if args.map else _default_map(args, robot)
    classes = SCENE_CLASSES if not args.flat_only else SCENE_CLASSES[:1]
    with _bars(args) as bars:
        bar = bars.counter(f"osrm experiment v{args.protocol}", scenes * len(classes) * len(seeds), "scenes")
        run = osrm_v3.run_osrm_v3 if v3 else osrm_v2.run_osrm_v2
        result = run(robot, rmap, seeds, scenes, grasps, args.tries, classes, bar)
    if before is not None:
        result = osrm_v3.with_v2(result, before) if v3 else osrm_v2.with_v1(result, before)
    result["seed_role"] = split or "other"

    def ci(v: Any) -> str:
        return "-" if v is None else f"{v[0]:.0f}-{v[1]:.0f}"

    lines = [f"{'scene':<16} {'strategy':<8} {'counted':>7} {'allowed':>7} {'N=1':>5} {'N=100':>6} {'95% CI':>8} "
             f"{'allowed N=100':>13} {'95% CI':>8} {'paper':>6} {'v2' if v3 else 'v1':>6}"]  # fmt: skip
    for r in result["rows"]:
        old = r.get("v2" if v3 else "v1")
        old_rate = None if old is None else old["success_allowed_N100" if v3 else "success_rate"]
        lines.append(f"{r['scene']:<16} {r['strategy']:<8} {r['counted_grasps']:>7} {r['allowed_grasps']:>7} "
                     f"{_cell(r['success_counted_N1'], '.1f'):>5} {_cell(r['success_counted_N100'], '.1f'):>6} "
                     f"{ci(r['ci95_counted_N100']):>8} {_cell(r['success_allowed_N100'], '.1f'):>13} "
                     f"{ci(r['ci95_allowed_N100']):>8} {_cell(r['paper_success_rate'], '.1f'):>6} "
                     f"{_cell(old_rate, '.1f'):>6}")  # fmt: skip
    lines.append(f"seeds {seeds} ({result['seed_role']}), {clock.seconds:.0f} s")
    result = _write_results(results_path, result, clock, lines, seeds=protocol.SEEDS, split=split, used_seeds=seeds,
                            protocol=(protocol.__doc__ or "").strip(), protocol_file=protocol_file)  # fmt: skip
    _emit(args, result, "\n".join(lines))
    return 0


def add_experiment_commands(sub: Any) -> None:
    """Add ``experiment SEGMENTATION|TABLE-GRID|INSPECT-TABLE|NAVIGATION|OSRM`` to ``baseplace``'s subparsers."""

    def command(name: str, help_text: str, func: Callable[[argparse.Namespace], int], parent: Any,
                description: str) -> argparse.ArgumentParser:  # fmt: skip
        p = parent.add_parser(name, help=help_text, description=description)
        p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
        p.set_defaults(func=func)
        return p

    experiment = sub.add_parser(
        "experiment",
        help="reproduce the papers' experiments on generated scenes",
        description="The papers' experiments: Birr et al., oriented surface reachability maps (segmentation, "
        "navigation, osrm); Hertle and Nebel, inverse surface reachability maps (inspect-table); Saini et al., "
        "robot placement for object grasping (table-grid).",
    )
    exp_sub = experiment.add_subparsers(
        dest="experiment", metavar="EXPERIMENT", parser_class=type(experiment)
    )
    exp_sub.required = True
    p = command("segmentation", "segmentation accuracy, baseline vs robust (Birr et al. VI)",
                cmd_experiment_segmentation, exp_sub,
                "Scenes per size class x {2, 4} planes, sigma 25 mm on the height map (Birr et al. VI) or on "
                "the cloud; share of cells on their true plane and normal error.")  # fmt: skip
    p.add_argument("--scenes", type=int, default=10, help="scenes per class and plane count (default 10)")
    p.add_argument("--noise", default="heightmap,cloud",
                   help='noise models, comma-separated: heightmap (the seed\'s), cloud (default "heightmap,cloud")')  # fmt: skip
    p.add_argument("--split", choices=("dev", "held-out"), default="held-out",
                   help="seed set: dev (choosing parameters) or held-out (reported; default)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=None, help="random seed (default: the split's)")
    p.add_argument("--results", default=None, help="write the results file (JSON with provenance) here")

    p = command("table-grid", "fixed pose vs radial vs IRM-verified on a 3 x 4 table grid (Saini et al.)",
                cmd_experiment_table_grid, exp_sub,
                "The seed's 0.74 x 0.8 x 1.8 m table, 20 cm cells, object-pose noise; the methods see a noisy "
                "cloud and the grid; success = a collision-free IK grasp of the true bottle exists from the chosen "
                "placement, checked against the true table and bottle.")  # fmt: skip
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    p.add_argument("--trials", type=int, default=5, help="trials per cell (default 5)")
    p.add_argument(
        "--no-feasible", action="store_true", help="skip the dense search for any working placement"
    )
    p.add_argument("--split", choices=("dev", "held-out"), default="held-out",
                   help="seed set: dev (choosing parameters) or held-out (reported; default)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=None, help="random seed (default: the split's)")
    p.add_argument("--surface-margin", type=float, default=None,
                   help="radial method's surface margin [m] (default: the value chosen on the dev seeds)")  # fmt: skip
    p.add_argument("--top-below", type=float, default=None,
                   help="IRM method's top-down grasps this far below the top [m] (default: chosen on dev)")  # fmt: skip
    p.add_argument("--out", default=None, help="PNG of the success heat maps (as Saini et al. Fig. 4)")
    p.add_argument("--results", default=None, help="write the results file (JSON with provenance) here")

    p = command("inspect-table", "predefined vs sampled poses for a PDDL inspect task (Hertle and Nebel)",
                cmd_experiment_inspect_table, exp_sub,
                "PR2 inspects every object on Hertle and Nebel's table (1.4 x 0.65 m); Fast Downward plans with 1-4 "
                "predefined poses or with poses the surface map's generator adds while planning. Needs "
                "pip install 'baseplace[planning]'.")  # fmt: skip
    p.add_argument("--objects", type=_int_list, default=[1, 2, 3, 4],
                   help='object counts, comma-separated (default "1,2,3,4")')  # fmt: skip
    p.add_argument("--runs", type=int, default=7, help="random layouts per object count (default 7)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--results", default=None, help="write the results file (JSON with provenance) here")

    p = command("navigation", "RRTConnect vs region-graph paths on multi-level scenes (Birr et al. V)",
                cmd_experiment_navigation, exp_sub,
                "{small, medium, large} x {2, 4} plane scenes; success, path length, time and ledge crossings "
                "checked against the true height field.")  # fmt: skip
    p.add_argument("--scenes", type=int, default=5, help="scenes per class (default 5)")
    p.add_argument("--pairs", type=int, default=12, help="start/goal pairs per scene (default 12)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--results", default=None, help="write the results file (JSON with provenance) here")

    p = command("osrm", "placement success and timing, Birr et al. Tables I and II", cmd_experiment_osrm, exp_sub,
                "Flat, {small, medium, large} x {2, 4} plane and incline-only scenes with a tray of objects; "
                "success at N = 1, 3, 10, 100 over grasps reachable by IK from some valid pose; only the hand "
                "may touch the grasped object.")  # fmt: skip
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    p.add_argument("--protocol", type=int, choices=(1, 2, 3), default=1,
                   help="1: one seed, as before; 2: docs/protocols/osrm_v2.md (three seeds, intervals, allowed grasps); "
                   "3: docs/protocols/osrm_v3.md (v2, the method's collision model from the clean cloud)")  # fmt: skip
    p.add_argument("--scenes", type=int, default=None,
                   help="scenes per class (protocol 1, default 10) or per seed and class (protocols 2 and 3, default 7)")  # fmt: skip
    p.add_argument("--grasps", type=int, default=None,
                   help="grasp candidates per scene (default: protocol 1 50, protocols 2 and 3 their fixed count)")  # fmt: skip
    p.add_argument("--tries", type=int, default=100, help="N: candidates per query (default 100)")
    p.add_argument("--split", choices=("dev", "held-out"), default=None,
                   help="protocols 2 and 3: the seed set, dev (default) or held-out (the reported tables)")  # fmt: skip
    p.add_argument(
        "--seeds",
        type=_int_list,
        default=None,
        help="protocols 2 and 3: seeds, comma-separated (default: the split's)",
    )
    p.add_argument(
        "--beside",
        default=None,
        help="protocol 2: a protocol-1 results file whose rows go beside; protocol 3: a protocol-2 one",
    )
    p.add_argument("--flat-only", action="store_true", help="Table I only")
    p.add_argument("--dev", action="store_true", help="run on the development seed (for choosing parameters)")
    p.add_argument("--results", default=None,
                   help="write the whole results file here (rows, seeds, command line, commit, wall time)")  # fmt: skip
    p.add_argument("--scheduler", default=None,
                   help='run scenes on a dask cluster: "tcp://host:port" or "local" (default: this process)')  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=2026,
                   help="scene seed (default 2026, the held-out seed the reported tables use)")  # fmt: skip
    p.add_argument("--out", default=None, help="PNG of the failure reasons (Fig. 5)")
