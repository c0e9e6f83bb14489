"""An honest first run (issue 29, item 3): one progress bar per map with its true total, the map's
build timed apart from the query, bars only on a terminal, no warnings, build-map and reach reusing
the cached default map."""

from __future__ import annotations

import json
import re
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from baseplace.cli import main
from baseplace.jobs import result_schema
from baseplace.jobs.text import report_text


def test_placement_png_with_motion_rejections_only_warns_nothing(tmp_path):
    from baseplace.viz.placement import plot_placement

    hmap = SimpleNamespace(shape=(20, 20), known=np.ones((20, 20), bool), origin=(0.0, 0.0), resolution=0.05)
    seg = SimpleNamespace(hmap=hmap, labels=np.zeros((20, 20), int), regions=[])
    osrm = SimpleNamespace(seg=seg, summed=np.ones((20, 20)), targets=[np.eye(4)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plot_placement(
            osrm,
            [],
            np.zeros((4, 2)),
            tmp_path / "p.png",
            "t",
            rejected=[((0.5, 0.5), "motion", ("arm_7_link", "obstacle"))],
        )
    assert (tmp_path / "p.png").stat().st_size > 0


def validate_result(obj: dict) -> None:
    import jsonschema

    jsonschema.validate(obj, result_schema())


SMALL = 2_000_000
"""Samples of the test's "default" map: built in about a second, as tiago_map in conftest."""
TARGET = "1.0 0.5 0.75 0 1.5708 0"


@pytest.fixture()
def small_default(monkeypatch, tmp_path):
    """A fresh, empty cache whose "default" map has SMALL samples (the true default takes ~50 s)."""
    import baseplace.reachability.build as build
    import baseplace.reachability.cache as cache

    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    full = build.BuildSettings
    for module in (build, cache):
        monkeypatch.setattr(module, "BuildSettings", lambda **kw: full(**{"samples": SMALL, **kw}))
    return tmp_path / "cache" / "maps"


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    cloud = tmp_path_factory.mktemp("scene") / "scene.npy"
    code = main(["scene", "generate", "--size-class", "medium", "--planes", "3", "--no-box", "--extent", "6",
                 "--seed", "2", "--out", str(cloud)])  # fmt: skip
    assert code == 0
    return cloud


def _on_a_terminal(monkeypatch, *args: str) -> tuple[int, str]:
    """``main(args)`` in this process with stderr on a pseudo-terminal (100 columns): (exit code, stderr)."""
    import fcntl
    import os
    import pty
    import struct
    import termios
    import threading

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    chunks: list[bytes] = []

    def drain() -> None:
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # the terminal closed
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=drain)
    reader.start()
    stream = open(slave, "w", buffering=1, encoding="utf-8")  # closed below
    try:
        with monkeypatch.context() as m:
            m.setattr(sys, "stderr", stream)
            assert sys.stderr.isatty()
            code = main(list(args))
    finally:
        stream.close()
        reader.join(timeout=10)
        os.close(master)
    return code, b"".join(chunks).decode(errors="replace")


def _bars(err: str) -> set[str]:
    """The descriptions of the progress bars drawn in ``err`` (tqdm's "desc:  42%|...")."""
    return set(re.findall(r"([A-Za-z][\w ,]*): +\d+%\|", err))


def test_a_fresh_cache_first_place_shows_one_bar_with_the_true_total(
    monkeypatch, small_default, scene, capsys
):
    code, err = _on_a_terminal(monkeypatch, "place", "--cloud", str(scene), "--target", TARGET)
    out = capsys.readouterr().out
    assert code == 0, err
    assert _bars(err) == {"reachability map, tiago arm"}, err  # one bar, named by the robot and its arm
    assert f"/{SMALL / 1e6:.2f}M" in err and "50.0M" not in err, err  # the build's true total
    assert "warning" not in err.lower(), err
    cached = list(small_default.glob("map-*.rmap"))
    assert len(cached) == 1
    assert "built the default reachability map in" in out and f"cached at {cached[0]}" in out, out
    code, err = _on_a_terminal(monkeypatch, "place", "--cloud", str(scene), "--target", TARGET)
    assert code == 0 and _bars(err) == set(), err  # the second run loads the cached map: no bar
    assert "built the default" not in capsys.readouterr().out


def test_the_first_place_times_the_map_build_apart_from_the_query(small_default, scene, capsys):
    code = main(["place", "--cloud", str(scene), "--target", TARGET, "--json"])
    obj = json.loads(capsys.readouterr().out)
    assert code == 0
    validate_result(obj)
    t = obj["timings_ms"]
    assert "map_build" in t and "map" not in t and t["map_build"] > 0, t
    assert obj["outputs"]["map"] == str(next(small_default.glob("map-*.rmap")))
    first_line = report_text(obj).splitlines()[0]
    assert first_line.endswith(f"({obj['strategy']}, {t['total'] - t['map_build']:.0f} ms)"), first_line
    assert main(["place", "--cloud", str(scene), "--target", TARGET, "--json"]) == 0
    t = json.loads(capsys.readouterr().out)["timings_ms"]  # the second: the cached map is loaded
    assert "map" in t and "map_build" not in t, t


def test_no_bars_and_no_warnings_on_a_redirected_stderr(monkeypatch, small_default, scene, tmp_path, capsys):
    log = tmp_path / "stderr.log"
    with open(log, "w") as stream, monkeypatch.context() as m:
        m.setattr(sys, "stderr", stream)
        code = main(["place", "--cloud", str(scene), "--target", TARGET, "--out", str(tmp_path / "p.png")])
    err = log.read_text()
    assert code == 0 and list(small_default.glob("map-*.rmap")), err  # the map was built in this run
    assert err == "", err  # no bar, no status line, no warning
    capsys.readouterr()


def test_build_map_reuses_the_cached_default_map_and_says_where(monkeypatch, small_default, tmp_path, capsys):
    from baseplace.reachability.storage import load_map

    first, second = tmp_path / "a.rmap", tmp_path / "b.rmap"
    assert main(["build-map", "--samples", str(SMALL), "--out", str(first)]) == 0
    out = capsys.readouterr().out
    cached = next(small_default.glob("map-*.rmap"))  # the default map built here is cached for place
    assert f"also cached at {cached}" in out, out
    code, err = _on_a_terminal(monkeypatch, "build-map", "--samples", str(SMALL), "--out", str(second))
    out = capsys.readouterr().out
    assert code == 0 and _bars(err) == set(), err  # not rebuilt: no sampling, no bar
    assert f"not rebuilt, the same map was already built and cached at {cached}" in out, out
    a, b = load_map(first), load_map(second)
    assert a.info == b.info and np.array_equal(a.cells, b.cells) and np.array_equal(a.counts, b.counts)
    assert main(["build-map", "--samples", str(SMALL), "--out", str(second), "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    validate_result(obj)
    assert obj["reused"] is True and obj["cached_at"] == str(cached)


def test_reach_without_map_uses_the_cached_default_map(small_default, capsys):
    query = ["--target", "0.6 0.1 0.8 0 1.5708 0", "--base", "0 0 0"]
    assert main(["reach", *query]) == 0  # no --map: the default map, built now and cached
    out = capsys.readouterr().out.splitlines()
    cached = next(small_default.glob("map-*.rmap"))
    assert out[1].startswith("built the default reachability map in") and str(cached) in out[1], out
    assert main(["reach", "--map", "default", *query, "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    validate_result(obj)
    assert [f"{v:.6g}" for v in obj["values"]] == out[:1] and "map" in obj["timings_ms"]
    assert main(["reach", "--map", str(cached), "--robot", "tiago", *query]) == 0
    assert capsys.readouterr().out.splitlines() == out[:1]


def test_surface_map_draws_one_bar_per_arm_named_by_it(monkeypatch, small_default, tmp_path):
    code, err = _on_a_terminal(monkeypatch, "surface-map", "--robot", "pr2", "--arms", "both", "--samples",
                               str(SMALL), "--polygon", "0,0;1.4,0;1.4,0.65;0,0.65", "--height", "0.74",
                               "--out", str(tmp_path / "t.smap"))  # fmt: skip
    assert code == 0, err
    assert _bars(err) == {"reachability map, pr2 left arm", "reachability map, pr2 right arm"}, err
