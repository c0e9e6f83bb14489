"""Per-arm FK kernels generated as Python source and compiled by numba.

The generic kernel in ``fk.py`` multiplies full 3x3 matrices for every joint. An arm's joint
placements are constants, mostly identities and axis permutations, and most joint axes are
aligned with a coordinate axis, so unrolling the chain symbolically with the constants folded
in removes most of the arithmetic. The source is written to a cache directory
(``$BASEPLACE_CACHE`` or ``~/.cache/baseplace``) and imported, so numba's on-disk cache holds
the machine code across processes. ``fk.py``'s generic kernel stays the test oracle. A cache
on a full disk costs the compilation, never the command: the kernels are then compiled from
memory, or numba's copy is skipped, with a one-line warning.
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from baseplace.files import cache_root, private_dir
from baseplace.robots.model import PRISMATIC, Arm

# Coefficients below this are dropped (URDF rpy values like 1.5708 leave ~5e-12 residues). Each
# dropped term moves the pose by < 1e-11 m or rad, so the kernel stays within ~1e-10 of pinocchio.
_EPS = 1e-11
# A term is (coefficient, factor); factor None is the constant 1, else a product expression.
Term = tuple[float, str | None]


def _combine(terms: list[Term]) -> list[Term]:
    out: dict[str | None, float] = {}
    for coef, factor in terms:
        out[factor] = out.get(factor, 0.0) + coef
    return [(c, f) for f, c in out.items() if abs(c) > _EPS]


def _expr(terms: list[Term]) -> str:
    parts = []
    for coef, factor in terms:
        if factor is None:
            parts.append(repr(float(coef)))
        elif coef == 1.0:
            parts.append(factor)
        elif coef == -1.0:
            parts.append(f"-{factor}")
        else:
            parts.append(f"{float(coef)!r} * {factor}")
    return " + ".join(parts).replace("+ -", "- ") if parts else "0.0"


def _times(value: list[Term], factor: str, coef: float) -> list[Term]:
    """Value * coef * factor, where value is a constant or a single variable."""
    out: list[Term] = []
    for c, f in value:
        out.append((c * coef, factor if f is None else f"{f} * {factor}"))
    return out


class _Emitter:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.count = 0

    def value(self, terms: list[Term]) -> list[Term]:
        """Bind a linear combination to a fresh variable unless it is a constant or a name."""
        terms = _combine(terms)
        if not terms or (len(terms) == 1 and (terms[0][1] is None or terms[0][0] == 1.0)):
            return terms
        self.count += 1
        name = f"v{self.count}"
        self.lines.append(f"    {name} = {_expr(terms)}")
        return [(1.0, name)]


def _const(x: float) -> list[Term]:
    return [(float(x), None)] if abs(x) > _EPS else []


def chain_source(arm: Arm) -> str:
    """Source of ``tcp_pose(q, R, t)`` for ``arm`` with every constant folded in."""
    em = _Emitter()
    P0 = arm.placements[0]
    R = [[_const(P0[a, b]) for b in range(3)] for a in range(3)]
    t = [_const(P0[a, 3]) for a in range(3)]

    def compose(P: np.ndarray) -> None:
        nonlocal R, t
        t = [em.value(t[a] + [tc for k in range(3) for tc in _scale(R[a][k], P[k, 3])]) for a in range(3)]
        R = [
            [em.value([tc for k in range(3) for tc in _scale(R[a][k], P[k, b])]) for b in range(3)]
            for a in range(3)
        ]

    for i in range(arm.n_joints):
        if i > 0:
            compose(arm.placements[i])
        axis = arm.axes[i]
        if arm.kinds[i] == PRISMATIC:
            q = f"q[{i}]"
            t = [
                em.value(t[a] + [tc for k in range(3) for tc in _times(R[a][k], q, axis[k])])
                for a in range(3)
            ]
            continue
        em.lines.append(f"    c{i} = math.cos(q[{i}])")
        em.lines.append(f"    s{i} = math.sin(q[{i}])")
        # Rodrigues: M = a a^T + c (I - a a^T) + s [a]_x, each entry split over {1, c, s}.
        aaT = np.outer(axis, axis)
        cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        K1, Kc, Ks = aaT, np.eye(3) - aaT, cross
        newR = []
        for a in range(3):
            row = []
            for b in range(3):
                terms: list[Term] = []
                for k in range(3):
                    terms += _scale(R[a][k], K1[k, b])
                    terms += _times(R[a][k], f"c{i}", Kc[k, b])
                    terms += _times(R[a][k], f"s{i}", Ks[k, b])
                row.append(em.value(terms))
            newR.append(row)
        R = newR
    compose(arm.T_last_tcp)
    body = em.lines
    for a in range(3):
        for b in range(3):
            body.append(f"    R[{a}, {b}] = {_expr(R[a][b])}")
        body.append(f"    t[{a}] = {_expr(t[a])}")
    return "\n".join(body)


def _scale(value: list[Term], coef: float) -> list[Term]:
    return [(c * coef, f) for c, f in value] if abs(coef) > _EPS else []


# No name or other text from a robot file goes into the source: only numbers formatted by repr
# and the variable names of this module (docs/security.md).
_TEMPLATE = '''"""Generated by baseplace.robots.codegen; do not edit (rewritten if it differs)."""
import math

import numba as nb
import numpy as np

from baseplace.reachability.grid import cell_of


@nb.njit(cache=True, inline="always")
def tcp_pose(q, R, t):
{body}


@nb.njit(cache=True, parallel=True)
def fk_batch(Q, out):
    for i in nb.prange(Q.shape[0]):
        R = np.empty((3, 3))
        t = np.empty(3)
        tcp_pose(Q[i], R, t)
        for a in range(3):
            for b in range(3):
                out[i, a, b] = R[a, b]
            out[i, a, 3] = t[a]
            out[i, 3, a] = 0.0
        out[i, 3, 3] = 1.0


@nb.njit(cache=True, parallel=True)
def bin_chunk(Q, origin, voxel_size, shape, nside, n_twist, pixel_phi, cells):
    for i in nb.prange(Q.shape[0]):
        R = np.empty((3, 3))
        t = np.empty(3)
        tcp_pose(Q[i], R, t)
        cells[i] = cell_of(R, t[0], t[1], t[2], origin, voxel_size, shape, nside, n_twist, pixel_phi)
'''

_loaded: dict[str, ModuleType] = {}


def cache_dir() -> Path:
    """Where generated kernels (and numba's compiled copies) are kept, in the per-user cache."""
    return cache_root() / "kernels"


def _kernel_file(directory: Path, key: str, source: str) -> Path:
    """The kernel file for ``key``, (re)written unless its bytes are exactly ``source``.

    The file is named by a SHA-256 of the source it must hold, and its bytes are compared with
    that source before every import: an edited or truncated file is replaced, never executed.
    """
    path = directory / f"chain_{key}.py"
    data = source.encode()
    try:
        current = path.read_bytes() if path.is_file() and path.stat().st_size == len(data) else None
    except OSError:
        current = None
    if current != data:
        from baseplace.files import write_bytes

        write_bytes(path, data, "kernel")
    return path


def _from_memory(name: str, source: str) -> ModuleType:
    """The kernel module compiled from ``source`` with numba's disk cache off (no file needed)."""
    module = ModuleType(name)
    sys.modules[name] = module
    exec(compile(source.replace("cache=True", "cache=False"), f"<{name}>", "exec"), module.__dict__)
    return module


def _skip_full_cache(module: ModuleType, directory: Path) -> None:
    """Let numba's cache of ``module``'s kernels skip a save that finds the disk full.

    numba raises the ``OSError`` of a failed cache save out of the compilation (it tolerates
    only Windows' permission errors), which would end a build over a cache.
    """
    from numba.core.dispatcher import Dispatcher

    from baseplace.files import is_disk_full, skip_cache_entry

    for kernel in vars(module).values():
        cache = getattr(kernel, "_cache", None) if isinstance(kernel, Dispatcher) else None
        if cache is None or not hasattr(cache, "save_overload"):
            continue

        def save_overload(sig: Any, data: Any, save: Any = cache.save_overload) -> None:
            try:
                save(sig, data)
            except OSError as exc:
                if not is_disk_full(exc):
                    raise
                skip_cache_entry("a compiled kernel", directory, exc)

        cache.save_overload = save_overload


def arm_kernels(arm: Arm) -> ModuleType:
    """The compiled module with ``tcp_pose``, ``fk_batch`` and ``bin_chunk`` for ``arm``."""
    source = _TEMPLATE.format(body=chain_source(arm))
    # a change in the binning code must not reuse stale kernels; imported here, not read from
    # sys.modules, because ``import baseplace`` no longer loads them (and not at the top: the
    # reachability package imports this module)
    deps = "".join(
        Path(m.__file__).read_text()
        for m in map(importlib.import_module, ("baseplace.reachability.grid", "baseplace.geometry.healpix"))
        if m.__file__
    )
    key = hashlib.sha256((source + deps).encode()).hexdigest()[:20]
    if key in _loaded:
        return _loaded[key]
    from baseplace.files import OutputError, skip_cache_entry

    name = f"baseplace_chain_{key}"
    try:
        path = _kernel_file(private_dir(cache_dir()), key, source)
    except OutputError as exc:
        skip_cache_entry("the kernels", cache_dir(), exc)
        module = _from_memory(name, source)
    else:
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # numba's cache re-imports the module by name
        spec.loader.exec_module(module)
        _skip_full_cache(module, path.parent)
    _loaded[key] = module
    return module
