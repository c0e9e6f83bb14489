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
    """Experiments import the library, never the reverse; only the CLI registers their commands."""
    import re
    from pathlib import Path

    src = Path(baseplace.__file__).parent
    imports = re.compile(r"^\s*(from|import) baseplace_experiments\b", re.MULTILINE)
    importers = sorted(str(p.relative_to(src)) for p in src.rglob("*.py") if imports.search(p.read_text()))
    assert importers == ["cli.py"]
    assert not list(src.glob("sim/*experiment*.py")) and not (src / "sim" / "results.py").exists()
