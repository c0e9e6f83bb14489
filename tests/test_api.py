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
