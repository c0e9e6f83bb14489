"""The import graph of ``baseplace`` (grimp, deferred imports included): no new circles, no arrow up.

Issue 26 asks for none of either. Today's circles and the one arrow up are listed here, so that a
change that adds another fails, and one that removes a listed one is told to strike it from the
list: the list only shrinks.
"""

from __future__ import annotations

import grimp
import networkx as nx

KNOWN_CIRCLES = []
"""Module circles still to be broken (issue 26)."""

LAYERS = ["cli", "serve", "jobs", "viz", "planning", "placement", "navigation", "io", "world", "reachability",
          "terrain", "robots", "geometry"]  # fmt: skip
"""The packages from the top down: a package imports only those below it (jobs draw their pictures with viz)."""

KNOWN_UPWARD: set[tuple[str, str]] = set()
"""Imports from a package to one above it still to be removed: none left."""


def _graph() -> nx.DiGraph:
    g = grimp.build_graph("baseplace", cache_dir=None)
    G = nx.DiGraph()
    for module in g.modules:
        G.add_node(module)
        for imported in g.find_modules_directly_imported_by(module):
            G.add_edge(module, imported)
    return G


def test_no_new_import_circles():
    found = [c for c in nx.strongly_connected_components(_graph()) if len(c) > 1]
    new = [sorted(c) for c in found if not any(c <= known for known in KNOWN_CIRCLES)]
    assert not new, f"new import circles: {new}"
    gone = [sorted(k) for k in KNOWN_CIRCLES if not any(k & c for c in found)]
    assert not gone, f"these circles are broken now: strike them from KNOWN_CIRCLES: {gone}"


def test_no_package_imports_a_package_above_it():
    rank = {name: k for k, name in enumerate(LAYERS)}

    def package(module: str) -> str | None:
        parts = module.split(".")
        return parts[1] if len(parts) > 1 and parts[1] in rank else None

    upward = set()
    for a, b in _graph().edges:
        pa, pb = package(a), package(b)
        if pa is not None and pb is not None and rank[pb] < rank[pa]:
            upward.add((a, b))
    assert upward <= KNOWN_UPWARD, f"imports up the layers: {sorted(upward - KNOWN_UPWARD)}"
    assert upward == KNOWN_UPWARD, f"removed: strike them from KNOWN_UPWARD: {sorted(KNOWN_UPWARD - upward)}"


def test_the_caches_find_their_folder_without_the_kernel_generator():
    """Issue 26's walk: the map and segmentation caches take the per-user cache folder from ``files``.

    Reading a cached map or segmentation needs no FK code generator.
    """
    g = _graph()
    for cache in ("baseplace.reachability.cache", "baseplace.terrain.cache", "baseplace.jobs.reach"):
        assert not g.has_edge(cache, "baseplace.robots.codegen"), cache
        assert g.has_edge(cache, "baseplace.files"), cache


def test_a_cached_segmentation_needs_no_diagnosis():
    """Issue 26's walk: ``terrain.pipeline`` imports the diagnosis of a failed segmentation where it segments."""
    import subprocess
    import sys

    code = (
        "import sys, baseplace.terrain.cache, baseplace.terrain.pipeline; "
        "sys.exit('baseplace.terrain.diagnose' in sys.modules)"
    )
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
