from __future__ import annotations

import importlib

import pytest

import baseplace

MODULES = [
    "baseplace",
    "baseplace.geometry",
    "baseplace.reachability",
    "baseplace.robots",
    "baseplace.terrain",
    "baseplace.sim",
    "baseplace.io",
    "baseplace_experiments.results",
]


@pytest.mark.parametrize("module", MODULES)
def test_every_public_name_imports(module):
    mod = importlib.import_module(module)
    for name in mod.__all__:
        assert getattr(mod, name) is not None, name


def test_errors_share_one_root():
    assert issubclass(baseplace.InputError, baseplace.BaseplaceError)
    assert issubclass(baseplace.NothingFoundError, baseplace.BaseplaceError)


def test_the_library_never_imports_the_experiments():
    """Experiments import the library, never the reverse: they register their commands as a plugin (test_plugins.py)."""
    import re
    from pathlib import Path

    src = Path(baseplace.__file__).parent
    imports = re.compile(r"^\s*(from|import) baseplace_experiments\b", re.MULTILINE)
    importers = sorted(str(p.relative_to(src)) for p in src.rglob("*.py") if imports.search(p.read_text()))
    assert importers == []
    assert not list(src.glob("sim/*experiment*.py")) and not (src / "sim" / "results.py").exists()


def test_the_jobs_and_their_settings_are_exported():
    """Issue 16 item 6: a user writes ``baseplace.place_job(baseplace.PlaceJob(...))`` without the CLI."""
    import baseplace.jobs.place
    import baseplace.navigation.planners
    import baseplace.placement.pipeline

    assert baseplace.place_job is baseplace.jobs.place.place_job
    assert baseplace.PlaceSettings is baseplace.placement.pipeline.PlaceSettings
    assert baseplace.plan_path is baseplace.navigation.planners.plan_path
    jobs = {n for n in baseplace.__all__ if n.endswith("_job")}
    assert jobs >= {"place_job", "candidates_job", "navigate_job", "surface_map_job", "surface_samples_job",
                    "reach_job", "build_map_job", "demo_job", "segment_job"}  # fmt: skip
    for name in jobs - {"robots_job", "occupancy_job"}:  # these two take no input object
        words = name.removesuffix("_job").split("_")
        assert "".join(w.title() for w in words) + "Job" in baseplace.__all__, name


def test_all_dir_and_the_lazy_names_agree():
    eager = {"BaseplaceError", "InputError", "NothingFoundError", "__version__"}
    assert set(baseplace.__all__) == eager | set(baseplace._LAZY)
    assert len(baseplace.__all__) == len(set(baseplace.__all__))
    assert set(baseplace.__all__) <= set(dir(baseplace))
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        _ = baseplace.not_a_name


def test_import_baseplace_loads_no_numba_and_no_robot_model():
    """``import baseplace`` is lazy (PEP 562): the heavy packages load on first use of a name."""
    import subprocess
    import sys

    code = "import sys, baseplace; print(sorted(m for m in ('numba', 'pinocchio', 'baseplace.reachability', 'baseplace.jobs', 'numpy') if m in sys.modules))"  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    code = "import sys, baseplace; baseplace.ReachabilityMap; print('baseplace.reachability' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


def test_reading_a_grid_or_a_map_loads_no_collision_model():
    """``baseplace.world`` is lazy too: the occupancy-grid and map loaders import neither coal nor
    pinocchio nor the scene model, and a public name of the package still resolves on first use."""
    import subprocess
    import sys

    heavy = ("coal", "pinocchio", "baseplace.world.environment", "scipy.spatial")
    code = (
        "import sys, baseplace.world.occupancy, baseplace.reachability.storage\n"
        f"print(sorted(m for m in {heavy!r} if m in sys.modules))\n"
        "from baseplace.world import GraspedObject, parse_obstacles\n"
        "print(GraspedObject.__module__, parse_obstacles.__module__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split("\n")[:2] == ["[]", "baseplace.world.grasped_object baseplace.world.obstacles"], out
