"""A command imports its own modules alone (issue 26: the ``place`` walk).

The parser lists the plugins' entry points without importing them, registers the service's
command only for ``serve``, and the other commands' job modules stay unexecuted.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import json, sys, types
from baseplace.cli import main
code = main(sys.argv[1:])
executed = sorted(n for n, m in sys.modules.items()
                  if n.split(".")[0] in ("baseplace", "baseplace_experiments", "numba", "coal", "pinocchio")
                  and type(m) is types.ModuleType)
sys.stderr.write("\\n" + json.dumps({"code": code, "modules": executed}) + "\\n")
"""

NOT_FOR_PLACE = (
    "baseplace.serve", "baseplace.serve.command", "baseplace_experiments", "baseplace_experiments.cli",
    "baseplace.viz", "baseplace.jobs.candidates", "baseplace.jobs.demo", "baseplace.jobs.explain",
    "baseplace.jobs.navigate", "baseplace.jobs.point", "baseplace.jobs.reach", "baseplace.jobs.surface",
    "baseplace.jobs.view", "baseplace.jobs.world", "baseplace.jobs.text", "baseplace.reachability.build",
)  # fmt: skip


def _modules(*argv: str) -> tuple[int, set[str]]:
    code, modules, _ = _run(*argv)
    return code, modules


def _run(*argv: str) -> tuple[int, set[str], str]:
    """The exit code, the modules executed and what the command wrote on stderr before them."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, env=env,
                         timeout=120)  # fmt: skip
    *before, last_line = out.stderr.strip().splitlines()
    last = json.loads(last_line)
    return last["code"], set(last["modules"]), "\n".join(before).strip()


def test_place_imports_neither_the_service_nor_the_plugins_nor_other_jobs(tmp_path):
    """A place that stops at its cloud (corrupt: read after the pipeline's imports) has imported its job, not another command's."""
    cloud = tmp_path / "corrupt.ply"
    cloud.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nend_header\n\x00")
    code, modules = _modules("place", "--cloud", str(cloud), "--target", "1 0.5 0.75 0 1.5708 0", "--json")
    assert code == 2
    assert "baseplace.jobs.place" in modules and "baseplace.placement.pipeline" in modules
    assert not modules & set(NOT_FOR_PLACE), sorted(modules & set(NOT_FOR_PLACE))


HEAVY = {"baseplace.placement.pipeline", "baseplace.world.environment", "numba", "coal", "pinocchio"}
"""What the pipeline imports (seconds): a mistyped argument is refused before any of it."""


def test_a_mistyped_argument_is_refused_before_the_pipelines_imports(tmp_path):
    """``place``, ``candidates``, ``navigate``, ``explain`` and ``surface-map`` check their inputs before the settings' imports."""
    cloud = tmp_path / "scene.ply"
    cloud.write_bytes(b"not read")
    target = "1 0.5 0.75 0 1.5708 0"
    mistakes = [
        ("place", "--cloud", str(tmp_path / "none.ply"), "--target", target),  # no such cloud file
        ("place", "--cloud", str(tmp_path / "scene.las"), "--target", target),  # no reader for the suffix
        ("place", "--cloud", str(tmp_path / ("a" * 300 + ".ply")), "--target", target),  # too long for the OS
        ("place", "--cloud", str(cloud), "--target", "1 0.5 0.75 0 1.5708"),  # 5 numbers
        ("place", "--cloud", str(cloud), "--target", target, "--out", str(tmp_path / "p.txt")),
        ("place", "--cloud", str(cloud), "--target", target, "--start", "1 2"),
        ("candidates", "--object", "1 2", "--occupancy", str(tmp_path / "none.yaml")),
        ("candidates", "--object", "1 2 0.8", "--cloud", str(cloud)),  # no occupancy grid
        ("navigate", "--start", "0 0 0", "--goal", "1 0 0"),  # no cloud
        ("navigate", "--cloud", str(tmp_path / "none.ply"), "--start", "0 0 0", "--goal", "1 0 0"),
        ("navigate", "--cloud", str(cloud), "--start", "0 0", "--goal", "1 0 0"),
        ("explain", "--cloud", str(cloud), "--target", target),  # no base pose
        ("explain", "--base", "0 0 0", "--target", target, "--floor", "0"),  # a floor without a cloud
        ("explain", "--cloud", str(tmp_path / "none.ply"), "--base", "0 0 0", "--target", target),
        (
            "surface-map",
            "--polygon",
            "0,0;1,0",
            "--height",
            "0.7",
            "--out",
            str(tmp_path / "s.smap"),
        ),  # 2 vertices
        (
            "candidates",
            "--object",
            "1 2 0.8",
            "--occupancy",
            str(tmp_path / "none.yaml"),
            "--robot-pose",
            "0 0",
        ),
    ]
    for argv in mistakes:
        code, modules = _modules(*argv)
        assert code == 2, argv
        assert not modules & HEAVY, (argv, sorted(modules & HEAVY))


def test_reach_and_view_refuse_a_missing_input_before_their_imports(tmp_path):
    """``reach`` without targets or bases is refused before the map's imports (numba), ``view`` of a
    missing result before the viewer's (viser, the robot's meshes): a third of a second, not one."""
    for argv in (("reach",), ("reach", "--target", "1 0.5 0.75 0 1.5708 0")):
        code, modules = _modules(*argv)
        assert code == 2, argv
        assert not modules & {"numba", "pinocchio", "baseplace.reachability.cache"}, (argv, sorted(modules))
    code, modules = _modules("view", str(tmp_path / "none.json"))
    assert code == 2
    assert "baseplace.jobs.view" in modules and "baseplace.viz.viewer" not in modules, sorted(modules)


def test_an_unknown_robot_is_refused_before_the_models_imports(tmp_path):
    """Every command taking ``--robot`` names a mistyped robot (or a missing robot file) before it
    imports pinocchio, coal or numba: half a second, not 1-3.6 s; the message is the loader's."""
    cloud = tmp_path / "scene.ply"
    cloud.write_bytes(b"not read")
    grid = tmp_path / "map.yaml"
    grid.write_text("not read")
    target = "1 0.5 0.75 0 1.5708 0"
    commands = [
        ("place", "--cloud", str(cloud), "--target", target),
        ("candidates", "--object", "1 2 0.8", "--occupancy", str(grid)),
        ("explain", "--cloud", str(cloud), "--base", "0 0 0", "--target", target),
        ("navigate", "--cloud", str(cloud), "--start", "0 0 0", "--goal", "1 0 0"),
        ("reach", "--target", target, "--base", "0 0 0"),
        ("build-map", "--out", str(tmp_path / "m.rmap")),
        ("surface-map", "--polygon", "0,0;1,0;1,1", "--height", "0.7", "--out", str(tmp_path / "s.smap")),
    ]
    heavy = {"numba", "coal", "pinocchio"}
    missing = tmp_path / "none.toml"
    cases = [(*argv, "--robot", "tiagoo") for argv in commands] + [("robot", "check", "tiagoo")]
    said = ["error: unknown robot 'tiagoo'; valid: "] * len(cases)
    # a missing robot file takes the same check (robots.spec.robot_file) in every command: two of them
    cases += [(*commands[0], "--robot", str(missing)), ("robot", "check", str(missing))]
    said += [f"error: robot file {missing} does not exist"] * 2
    for argv, message in zip(cases, said, strict=True):
        code, modules, stderr = _run(*argv)
        assert code == 2 and stderr.startswith(message), (argv, stderr)
        assert not modules & heavy, (argv, sorted(modules & heavy))


def test_a_mistyped_arm_or_a_missing_map_file_is_refused_before_the_imports(tmp_path):
    """``--arm`` is checked against the robot's spec, ``--map`` (a reachability or surface map) for
    being there and ``--clearance`` for its range, before numba, coal or pinocchio are imported;
    the messages are the loaders' and the settings'."""
    cloud = tmp_path / "scene.ply"
    cloud.write_bytes(b"not read")
    grid = tmp_path / "map.yaml"
    grid.write_text("not read")
    target = "1 0.5 0.75 0 1.5708 0"
    missing = tmp_path / "none.rmap"
    jobs = [
        ("place", "--cloud", str(cloud), "--target", target),
        ("candidates", "--object", "1 2 0.8", "--occupancy", str(grid)),
        ("explain", "--cloud", str(cloud), "--base", "0 0 0", "--target", target),
    ]
    cases = [(*argv, "--arm", "left") for argv in jobs] + [
        ("build-map", "--out", str(tmp_path / "m.rmap"), "--arm", "left")
    ]
    said = ["error: unknown arm 'left' of robot 'tiago'; valid: arm"] * len(cases)
    cases += [(*argv, "--map", str(missing)) for argv in jobs] + [
        ("reach", "--target", target, "--base", "0 0 0", "--map", str(missing))
    ]
    said += [f"error: map file {missing} does not exist"] * (len(jobs) + 1)
    cases.append(("surface-sample", "--map", str(tmp_path / "none.smap")))
    said.append(f"error: surface map {tmp_path / 'none.smap'} does not exist")
    cases += [(*argv, "--clearance", "0.2") for argv in jobs]
    said += ["error: clearance must be a finite distance in [0, 0.1] m, got 0.2"] * len(jobs)
    for argv, message in zip(cases, said, strict=True):
        code, modules, stderr = _run(*argv)
        assert code == 2 and stderr == message, (argv, stderr)
        assert not modules & {"numba", "coal", "pinocchio"}, (argv, sorted(modules))


def test_serve_help_still_registers_the_service():
    out = subprocess.run([sys.executable, "-m", "baseplace.cli", "serve", "--help"], capture_output=True,
                         text=True, timeout=120)  # fmt: skip
    assert out.returncode == 0 and "usage: baseplace serve" in out.stdout and "--max-scenes" in out.stdout


def test_candidates_without_a_grid_name_what_to_give():
    """Candidates stand on an occupancy grid: asked for without one, the error says which options give it."""
    from conftest import run_cli

    for argv in (("--object", "1 2 0.8"), ("--object", "1 2 0.8", "--bag", "run.bag")):
        proc = run_cli("candidates", *argv)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr == "error: give --occupancy MAP.yaml or --bag FILE --map-topic TOPIC\n", (
            proc.stderr
        )
