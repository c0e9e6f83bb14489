"""Fuzz targets shared by ``tests/test_fuzz.py`` (CI budget) and ``bench/fuzz.py`` (full budget).

Issue 9.3: every loader and the pose parsers must, for any input, either load or raise a clean
:class:`~baseplace.errors.BaseplaceError` with a one-line message; never another exception, a
crash or a hang. A :class:`Target` couples a hypothesis strategy of cases with a function that
writes the case to a scratch directory and calls the loader; :func:`run_case` runs it under a time
limit and sorts the result into an outcome:

* ``loaded``: the loader returned (``note`` may flag a loaded value that breaks an invariant, e.g.
  a non-finite footprint; such notes are reported, they do not fail the tests);
* ``clean``: a :class:`BaseplaceError` with a non-empty one-line message;
* ``crash``: any other exception (or a multi-line/empty BaseplaceError message);
* ``hang``: the case ran past the time limit (SIGALRM; a loop stuck in native code is caught by
  the bench's per-worker timeout instead);
* ``violated``: a property target's assertion failed (pose math).

Cases are structured where the format has structure (a valid header with mutated fields, counts,
types; truncated, flipped or extended data; NaN/inf values) and random bytes or text elsewhere.
Bulk numbers inside a case come from a numpy generator seeded by hypothesis, so cases stay cheap
to draw and exactly reproducible from the seed.

Known bugs: :data:`KNOWN_BUGS` lists the open library bugs by the signature of the crash or hang
they cause; the CI fuzz tests accept a crash that matches one, and ``tests/test_fuzz.py`` holds a
strict-xfail reproducer for each. When a bug is fixed its reproducer XPASSes (a strict failure):
move its entry to :data:`FIXED_BUGS`, which turns the reproducer into a plain regression test.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import math
import re
import shutil
import signal
import struct
import traceback
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import h5py
import lzf
import numpy as np
import yaml
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from baseplace.errors import BaseplaceError

DATA = Path(__file__).parent / "data"

LOADED, CLEAN, CRASH, HANG, VIOLATED = "loaded", "clean", "crash", "hang", "violated"
OUTCOMES = (LOADED, CLEAN, CRASH, HANG, VIOLATED)

CI_SETTINGS = settings(
    derandomize=True,
    deadline=None,
    database=None,
    print_blob=False,
    suppress_health_check=list(HealthCheck),
)
"""Base settings of the CI fuzz tests: reproducible (derandomized), no deadline, no database."""


# --------------------------------------------------------------------------------------------
# running one case
# --------------------------------------------------------------------------------------------


class Hang(BaseException):  # a BaseException: no `except Exception` in the library swallows it
    """Raised by the alarm when a case runs past its time limit."""


@contextlib.contextmanager
def _alarm(seconds: float) -> Iterator[None]:
    def fire(signum: int, frame: Any) -> None:
        raise Hang(f"case ran past {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@dataclass
class Result:
    """What one case did."""

    outcome: str
    signature: str = ""  # exception type and where it was raised (crash, hang, violated)
    message: str = ""  # first line of the exception message
    note: str = ""  # loaded, but an invariant is broken
    warnings: int = 0  # Python warnings emitted
    peak_bytes: int = 0  # growth of the peak resident memory during the case


def _where(exc: BaseException) -> str:
    """The deepest frame inside baseplace (else the deepest frame) of an exception's traceback."""
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return "?"
    ours = [f for f in frames if "/baseplace/" in f.filename]
    f = (ours or frames)[-1]
    short = f.filename.split("/src/")[-1].split("site-packages/")[-1]
    return f"{short}:{f.lineno} {f.name}"


def _first_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    text = lines[0] if lines else ""
    return text if len(text) <= 200 else text[:197] + "..."


MEMORY_MULTIPLE = 100
"""A case may grow the process's peak resident memory by at most this many times its input's bytes
(plus :data:`MEMORY_SLACK`); more is a crash (issue 15: bounded memory before allocation)."""
MEMORY_SLACK = 256 * 2**20  # bytes: imports, numba compiles and HDF5 caches of a first case


def _status_kib(field: str) -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def _reset_peak_rss() -> bool:
    """Reset the kernel's peak resident size of this process (VmHWM); False where unsupported."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _input_bytes(workdir: Path) -> int:
    return sum(p.stat().st_size for p in workdir.rglob("*") if p.is_file())


def run_case(target: Target, case: Any, workdir: Path, time_limit: float = 10.0) -> Result:
    """Run ``case`` of ``target`` in an emptied ``workdir``; classify the result, note its peak memory.

    The peak is the growth of the process's peak resident memory (``VmHWM`` after a reset, less
    the resident size before), so allocations in C count too. A case whose peak exceeds
    ``MEMORY_MULTIPLE`` x its input bytes + ``MEMORY_SLACK`` is a crash ("MemoryBlowup"), even
    if it ended in a clean error.
    """
    measured = _reset_peak_rss()
    before = _status_kib("VmRSS") or 0
    result = _run_case(target, case, workdir, time_limit)
    peak = _status_kib("VmHWM") if measured else None
    if peak is not None:
        result.peak_bytes = max(0, peak - before) * 1024
        allowed = MEMORY_MULTIPLE * _input_bytes(workdir) + MEMORY_SLACK
        if result.peak_bytes > allowed and result.outcome in (LOADED, CLEAN):
            return Result(CRASH, f"MemoryBlowup @ {target.name}",
                          f"peak {result.peak_bytes / 2**20:.0f} MiB > {allowed / 2**20:.0f} MiB allowed",
                          warnings=result.warnings, peak_bytes=result.peak_bytes)  # fmt: skip
    return result


def _run_case(target: Target, case: Any, workdir: Path, time_limit: float = 10.0) -> Result:
    shutil.rmtree(workdir, ignore_errors=True)
    workdir.mkdir(parents=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with _alarm(time_limit):
                note = target.run(case, workdir)
        except Hang as exc:
            return Result(HANG, f"Hang @ {_where(exc)}", str(exc), warnings=len(caught))
        except BaseplaceError as exc:
            text = str(exc)
            if not text.strip() or "\n" in text or "\r" in text:
                sig = f"{type(exc).__name__} (multi-line or empty message) @ {_where(exc)}"
                return Result(CRASH, sig, text[:200], warnings=len(caught))
            note = f"message of {len(text)} chars" if len(text) > 2000 else ""
            return Result(CLEAN, message=_first_line(exc), note=note, warnings=len(caught))
        except AssertionError as exc:  # a property's check failed, or an assert in the library
            outcome = VIOLATED if target.kind == "property" else CRASH
            return Result(outcome, f"AssertionError @ {_where(exc)}", _first_line(exc), warnings=len(caught))
        except Exception as exc:
            return Result(
                CRASH, f"{type(exc).__name__} @ {_where(exc)}", _first_line(exc), warnings=len(caught)
            )
    return Result(LOADED, note=note or "", warnings=len(caught))


@dataclass(frozen=True)
class KnownBug:
    """A confirmed library bug, recognised by the crash it causes in one or more targets."""

    id: str
    targets: tuple[str, ...]
    signature: str  # regex on Result.signature
    message: str = ""  # regex on Result.message
    reason: str = ""


KNOWN_BUGS: list[KnownBug] = []
"""Open library bugs, each with a strict-xfail reproducer in tests/test_fuzz.py (move it to FIXED_BUGS when fixed)."""

FIXED_BUGS: list[KnownBug] = [
    KnownBug(
        "transform-long-text",
        ("transform_text",),
        r"^OSError @ baseplace/terrain/io\.py:\d+ load_transform$",
        "File name too long",
        "load_transform: Path(spec).is_file() raises OSError (ENAMETOOLONG) for a text of > 255 bytes, e.g. "
        "16 numbers typed inline; pathlib only swallows ENOENT/ENOTDIR/EBADF/ELOOP",
    ),
    KnownBug(
        "transform-tilde-user",
        ("transform_text",),
        r"^(RuntimeError|ValueError) @ baseplace/terrain/io\.py:\d+ load_transform$",
        "home directory",
        "load_transform: Path(spec).expanduser() raises RuntimeError for '~name...' of an unknown user",
    ),
    KnownBug(
        "yaml-toml-deep-nesting",
        ("occupancy", "robot_file"),
        r"^RecursionError @ baseplace/(world/occupancy\.py:\d+ _read_yaml|robots/spec\.py:\d+ load_spec)$",
        "",
        "PyYAML and tomllib recurse per nesting level; '[' * 600 raises RecursionError, which "
        "_read_yaml and load_spec do not catch",
    ),
    KnownBug(
        "yaml-alias-repr",
        ("occupancy", "robot_file"),
        r"^Hang @ baseplace/(world/occupancy|robots/spec)\.py:\d+ ",
        "",
        "a YAML alias bomb (~500 bytes standing for a list of 10**8 items) passes safe_load; load_occupancy "
        "puts repr(value) in its error message and spec_from_dict takes str(value) as a name: 39 s and 0.5 GB "
        "at 8 levels, 10x per level; the fuzz strategies stop at 6 levels (5 MB messages, reported as notes)",
    ),
    KnownBug(
        "rmap-attributes-unchecked",
        ("rmap_h5", "rmap_bytes"),
        r"^(TypeError|KeyError|AttributeError|IndexError|ValueError|RecursionError|MemoryError|OverflowError) "
        r"@ baseplace/reachability/(storage|grid|rmap)\.py:\d+ ",
        "",
        "load_map: the grid/info JSON attributes are decoded inside the try but used after it (MapInfo(**info), "
        "SE3Grid(...), cells.astype) and the try does not catch RecursionError (deep JSON) or MemoryError; the "
        "sha256 covers the datasets only, so a flipped byte in an attribute reaches that code",
    ),
    KnownBug(
        "rmap-grid-unbounded",
        ("rmap_h5",),
        r"^(Hang|MemoryError|ValueError|OverflowError) @ baseplace/geometry/healpix\.py:\d+ pix2ang_ring$",
        "",
        "load_map builds SE3Grid(nside from the file): pix2ang_ring loops in Python over 12 nside^2 pixels "
        "(nside 1024: 12 s; 65536: hours) or cannot allocate them; nothing bounds nside",
    ),
    KnownBug(
        "smap-meta-unchecked",
        ("smap_h5", "smap_bytes"),
        r"^(TypeError|KeyError|AttributeError|IndexError|ValueError|RecursionError|MemoryError|OverflowError) "
        r"@ baseplace/placement/(surface_storage|surface_map)\.py:\d+ ",
        "",
        "load_surface_map: meta['origin'/'resolution'/'polygon'/...] are read after the try, and the try does "
        "not catch MemoryError (np.zeros(prod(shape)) of a huge shape) or RecursionError",
    ),
    KnownBug(
        "polygon-ragged-array",
        ("polygon",),
        r"^(ValueError|TypeError) @ baseplace/placement/surface_map\.py:\d+ parse_polygon$",
        "",
        "parse_polygon(array-like): np.asarray(text, dtype=float) is outside any try; a ragged list or "
        "strings raise numpy's ValueError instead of InputError",
    ),
    KnownBug(
        "up-vector-extreme",
        ("transform_text",),
        r"^$",
        "",
        "up_vector_transform: np.linalg.norm(u) overflowed for components >~ 1e154 (u / inf = 0, so the 180 deg "
        "branch was taken: '1e200 1e200 1' flipped the cloud upside down) and underflowed below ~1e-154 "
        "('must be non-zero'); found as a 'loaded' note, not a crash",
    ),
    KnownBug(
        "hdf5-global-heap-hang",
        ("rmap_bytes", "smap_bytes", "rmap_h5", "smap_h5"),
        r"^Hang @ baseplace/(reachability/storage\.py:\d+ load_map|placement/surface_storage\.py:\d+ load_surface_map)$",
        "native code",
        "HDF5 2.0.0 (h5py 3.16.0) never returns from reading a variable-length string attribute when the "
        "global heap collection (GCOL) holding it is corrupt, e.g. one flipped byte in its size field; it holds "
        "the GIL, so no signal or thread can stop it. Format version 1 stored format/grid/info/meta/sha256 as vlen "
        "strings; version 2 stores texts as uint8 datasets inside the checksum, and no loader reads a vlen string "
        "(baseplace.h5files)",
    ),
    KnownBug(
        "hdf5-runtime-error",
        ("rmap_bytes", "smap_bytes", "rmap_h5", "smap_h5"),
        r"^RuntimeError @ baseplace/(reachability/storage\.py:\d+ load_map|placement/surface_storage\.py:\d+ "
        r"load_surface_map)$",
        "",
        'h5py raises RuntimeError (not OSError) for some corrupt files, e.g. `"manipulability" in f` '
        "(H5Lexists: 'unable to offset into local heap data block') after one flipped byte; load_map and "
        "load_surface_map do not catch RuntimeError",
    ),
    KnownBug(
        "occupancy-mode-str",
        ("occupancy",),
        r"^Hang @ baseplace/world/occupancy\.py:\d+ ",
        "",
        "load_occupancy takes str(doc['mode']) before checking it is a string: a 'mode' that is a YAML alias "
        "bomb becomes a 10**levels-item string (the error message of 5 MB at 6 levels, 39 s and 0.5 GB at 8)",
    ),
]
"""Bugs this fuzzing found that have been fixed since; their reproducers in tests/test_fuzz.py are regression tests."""


def known_bug(target: str, result: Result, include_fixed: bool = False) -> KnownBug | None:
    """The open bug (or with ``include_fixed`` also the fixed one) a crash or hang of ``target`` matches."""
    if result.outcome not in (CRASH, HANG):
        return None
    for bug in KNOWN_BUGS + (FIXED_BUGS if include_fixed else []):
        if (
            target in bug.targets
            and re.search(bug.signature, result.signature)
            and re.search(bug.message, result.message)
        ):
            return bug
    return None


def describe(case: Any, limit: int = 400) -> str:
    """A short repr of a case for reports."""
    text = repr(case)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Target:
    """One fuzz target: a strategy of cases and a runner (case, scratch dir) -> note or None."""

    name: str
    strategy: st.SearchStrategy[Any]
    run: Callable[[Any, Path], str | None]
    kind: str = "loader"  # or "property"
    ci_examples: int = 150
    doc: str = ""


# --------------------------------------------------------------------------------------------
# building blocks: numbers, tokens, mutations
# --------------------------------------------------------------------------------------------

SEEDS = st.integers(0, 2**32 - 1)
NASTY_FLOATS = st.sampled_from(
    [
        math.nan,
        -math.nan,
        math.inf,
        -math.inf,
        0.0,
        -0.0,
        1e308,
        -1e308,
        5e-324,
        1e-300,
        3.5e38,
        65504.0,
        1e20,
    ]
)
ANY_FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), NASTY_FLOATS)
KEYWORDS = [
    "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e999", "-1e999", "0", "-0", "1", "-1", "0x10", "1_000",
    "1e", ".", "", " ", "~", "~/x", "#", ",", ";", "[", "]", "\x00", "\t", "é", "\u0661\u0662", "ascii", "binary",
    "binary_compressed", "F", "I", "U", "x", "y", "z", "rgb", "rgba", "float", "double", "uchar", "int", "list",
    "vertex", "face", "element", "property", "end_header", "OcTree", "ColorOcTree", "data", "size", "res",
    "True", "None", "null", "4294967295", "4294967296", "18446744073709551616", "-2147483649",
]  # fmt: skip
TOKENS = st.one_of(
    st.integers(-3, 40).map(str),
    st.integers(-(2**66), 2**66).map(str),
    ANY_FLOATS.map(repr),
    st.sampled_from(KEYWORDS),
    st.text(max_size=8),
    st.text(alphabet="0123456789.-+eE", max_size=8),
)
NUMBER_TOKENS = st.one_of(
    st.floats(-100, 100).map(repr),
    st.integers(-100, 100).map(str),
    ANY_FLOATS.map(repr),
    st.sampled_from(
        ["nan", "inf", "-inf", "1e999", "1e-400", "0x1p3", "1_0", "+1", "-0", "\u0661", "abc", "", "e"]
    ),
)
SEPARATORS = st.sampled_from([" ", " ", ",", ", ", "\t", "  ", ";", " , "])


def chance(p: float) -> st.SearchStrategy[bool]:
    """True with probability about ``p``."""
    return st.integers(0, 999).map(lambda v: v < p * 1000)


_INDEX = st.integers(0, 2**16)
_LINE_OP = st.one_of(
    st.tuples(st.just("replace"), _INDEX, _INDEX, TOKENS),
    st.tuples(st.just("delete"), _INDEX),
    st.tuples(st.just("dup"), _INDEX),
    st.tuples(st.just("insert"), _INDEX, st.lists(TOKENS, max_size=4).map(" ".join)),
    st.tuples(st.just("swap"), _INDEX, _INDEX),
    st.tuples(st.just("drop_token"), _INDEX, _INDEX),
    st.tuples(st.just("add_token"), _INDEX, TOKENS),
    st.tuples(st.just("space"), _INDEX, st.sampled_from(["lead", "trail", "crlf", "tab", "upper", "lower"])),
)
LINE_OPS = st.one_of(st.just([]), st.lists(_LINE_OP, min_size=1, max_size=3))
"""Mutations of a list of text lines (header lines, text data), none half of the time; indices wrap around."""

_POS = st.one_of(st.integers(0, 4095), st.integers(0, 2**31))
_BYTE_OP = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), _POS, st.integers(1, 255)),
    st.tuples(st.just("insert"), _POS, st.binary(min_size=1, max_size=16)),
    st.tuples(st.just("delete"), _POS, st.integers(1, 64)),
    st.tuples(st.just("overwrite"), _POS, st.binary(min_size=1, max_size=16)),
    st.tuples(st.just("append"), st.binary(min_size=1, max_size=64)),
)
BYTE_OPS = st.one_of(st.just([]), st.lists(_BYTE_OP, min_size=1, max_size=3))
"""Mutations of bytes, none half of the time; positions wrap around (small ones hit headers more often)."""


def apply_line_ops(lines: list[str], ops: list[tuple[Any, ...]]) -> list[str]:
    """Apply :data:`LINE_OPS` to a copy of ``lines``."""
    lines = list(lines)
    for op in ops:
        kind = op[0]
        if kind == "insert":
            lines.insert(op[1] % (len(lines) + 1), op[2])
            continue
        if not lines:
            continue
        i = op[1] % len(lines)
        words = lines[i].split(" ")
        if kind == "replace":
            words[op[2] % len(words)] = op[3]
            lines[i] = " ".join(words)
        elif kind == "delete":
            del lines[i]
        elif kind == "dup":
            lines.insert(i, lines[i])
        elif kind == "swap":
            j = op[2] % len(lines)
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "drop_token":
            del words[op[2] % len(words)]
            lines[i] = " ".join(words)
        elif kind == "add_token":
            lines[i] = f"{lines[i]} {op[2]}"
        elif kind == "space":
            lines[i] = {
                "lead": " " + lines[i],
                "trail": lines[i] + " ",
                "crlf": lines[i] + "\r",
                "tab": lines[i].replace(" ", "\t"),
                "upper": lines[i].upper(),
                "lower": lines[i].lower(),
            }[op[2]]
    return lines


def apply_byte_ops(data: bytes, ops: list[tuple[Any, ...]]) -> bytes:
    """Apply :data:`BYTE_OPS` to ``data``."""
    buf = bytearray(data)
    for op in ops:
        kind = op[0]
        if kind == "truncate":
            del buf[int(op[1] * len(buf)) :]
        elif kind == "append":
            buf += op[1]
        elif not buf:
            continue
        elif kind == "flip":
            buf[op[1] % len(buf)] ^= op[2]
        elif kind == "insert":
            p = op[1] % (len(buf) + 1)
            buf[p:p] = op[2]
        elif kind == "delete":
            p = op[1] % len(buf)
            del buf[p : p + op[2]]
        elif kind == "overwrite":
            p = op[1] % len(buf)
            buf[p : p + len(op[2])] = op[2]
    return bytes(buf)


def _numbers(rng: np.random.Generator, dtype: np.dtype, n: int) -> np.ndarray:
    """``n`` random values of a numeric dtype: floats of random magnitude, ints over the full range."""
    if dtype.kind == "f":
        scale = 10.0 ** rng.integers(-3, 4)
        with np.errstate(over="ignore"):
            return (rng.normal(0.0, scale, n)).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(
        info.min, info.max, size=n, endpoint=True, dtype=np.int64 if info.min < 0 else np.uint64
    )


INJECTIONS = st.lists(st.tuples(st.floats(0, 1), NASTY_FLOATS), max_size=4)
"""Special float values put at random places of a float column: NaN, inf, extremes."""


def _inject(column: np.ndarray, injections: list[tuple[float, float]]) -> None:
    if column.dtype.kind != "f" or column.size == 0:
        return
    flat = column.reshape(-1)
    with np.errstate(over="ignore", invalid="ignore"):
        for frac, value in injections:
            flat[min(int(frac * flat.size), flat.size - 1)] = value


YAML_VALUES: st.SearchStrategy[Any] = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | ANY_FLOATS | st.text(max_size=10),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4)
    ),
    max_leaves=8,
)
"""Anything YAML or JSON can hold (TOML less None)."""

DEEP_NESTING = st.sampled_from([10, 50, 100, 2500]).map(lambda n: "[" * n + "]" * n)
"""Nested lists; 2500 levels exceed the recursion limit even under hypothesis (which raises it to ~2000)."""


def alias_bomb(levels: int, key: str = "image") -> str:
    """A YAML line ``key: &a{levels-1} [&a{levels-2} [...], *a{levels-2} x 9]``: 10 ** levels items.

    A few hundred bytes; PyYAML shares the aliased lists, so parsing is cheap, but ``str()`` or
    ``repr()`` of the value (an error message) grows tenfold with each level.
    """
    value = "&a0 [" + ", ".join(["x"] * 10) + "]"
    for i in range(1, levels):
        value = f"&a{i} [{value}, " + ", ".join([f"*a{i - 1}"] * 9) + "]"
    return f"{key}: {value}\n"


ALIAS_LEVELS = st.sampled_from([2, 4, 6])


# --------------------------------------------------------------------------------------------
# point clouds
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FileCase:
    """A file to write (name in the scratch directory, content) and load."""

    name: str
    data: bytes

    def __repr__(self) -> str:
        return f"FileCase({self.name!r}, {self.data[:600]!r}{'...' if len(self.data) > 600 else ''} [{len(self.data)} bytes])"


def _load_cloud(case: FileCase, workdir: Path) -> str | None:
    from baseplace.terrain.io import load_cloud

    path = workdir / case.name
    path.write_bytes(case.data)
    cloud = load_cloud(path)
    if len(cloud) == 0 or not np.isfinite(cloud.points).all():
        return "loaded an empty or non-finite cloud"
    if cloud.colors is not None and cloud.colors.shape != cloud.points.shape:
        return "colors do not match the points"
    return None


PCD_FIELDS = ["x", "y", "z", "rgb", "rgba", "r", "g", "b", "intensity", "normal_x", "_", "label"]
PCD_TYPES = [
    ("F", 4),
    ("F", 8),
    ("I", 1),
    ("I", 2),
    ("I", 4),
    ("I", 8),
    ("U", 1),
    ("U", 2),
    ("U", 4),
    ("U", 8),
]
PCD_NUMPY = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "<i1", ("I", 2): "<i2", ("I", 4): "<i4",
             ("I", 8): "<i8", ("U", 1): "<u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}  # fmt: skip


def _with_xyz(draw: Any, names: list[str], p: float = 0.85) -> list[str]:
    names = list(names)
    if draw(chance(p)):
        for f in "xyz":
            if f not in names:
                names.insert(draw(st.integers(0, len(names))), f)
    return names


def _float_text(v: Any) -> str:
    return repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)


@st.composite
def pcd_files(draw: Any) -> FileCase:
    """A PCD file: ascii, binary or binary_compressed, random fields/types/counts, then mutated."""
    names = _with_xyz(draw, draw(st.lists(st.sampled_from(PCD_FIELDS), max_size=5, unique=True)))
    types = [draw(st.sampled_from([("F", 4), ("F", 4), *PCD_TYPES])) for _ in names]
    counts = [draw(st.sampled_from([1, 1, 1, 1, 2, 3])) for _ in names]
    if draw(st.booleans()):
        width, height = draw(st.integers(1, 6)), draw(st.integers(1, 5))
    else:
        width, height = draw(st.integers(0, 40)), 1
    n = width * height
    encoding = draw(st.sampled_from(["ascii", "binary", "binary_compressed"]))
    rng = np.random.default_rng(draw(SEEDS))
    injections = draw(INJECTIONS)
    columns = []
    for t, c in zip(types, counts, strict=True):
        col = np.asarray(_numbers(rng, np.dtype(PCD_NUMPY[t]), n * c)).astype(PCD_NUMPY[t]).reshape(n, c)
        _inject(col, injections)
        columns.append(col)
    header = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        "FIELDS " + " ".join(names),
        "SIZE " + " ".join(str(t[1]) for t in types),
        "TYPE " + " ".join(t[0] for t in types),
        "COUNT " + " ".join(map(str, counts)),
        f"WIDTH {width}",
        f"HEIGHT {height}",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        f"DATA {encoding}",
    ]
    if encoding == "ascii":
        rows = [" ".join(_float_text(v) for col in columns for v in col[i]) for i in range(n)]
        rows = apply_line_ops(rows, draw(LINE_OPS))
        body = ("\n".join(rows) + "\n").encode() if rows else b""
    elif encoding == "binary":
        body = b"".join(columns[j][i].tobytes() for i in range(n) for j in range(len(columns)))
    else:
        raw = b"".join(np.ascontiguousarray(col.T).tobytes() for col in columns)  # column by column
        packed = lzf.compress(raw, len(raw) + len(raw) // 16 + 64) if raw else b""
        body = struct.pack("<II", len(packed), len(raw)) + packed if raw else b""
    header = apply_line_ops(header, draw(LINE_OPS))
    data = ("\n".join(header) + "\n").encode() + apply_byte_ops(body, draw(BYTE_OPS))
    return FileCase(draw(st.sampled_from(["cloud.pcd", "cloud.pcd", "cloud.PCD"])), data)


PLY_TYPES = {"char": "b", "uchar": "B", "short": "h", "ushort": "H", "int": "i", "uint": "I", "float": "f",
             "double": "d", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i",
             "uint32": "I", "float32": "f", "float64": "d"}  # fmt: skip
PLY_SCALARS = st.sampled_from(["float", "float", "double", *PLY_TYPES])
PLY_COUNT_TYPES = st.sampled_from(["uchar", "uint8", "int", "ushort", "char"])


def _ply_value(rng: np.random.Generator, code: str, injections: list[tuple[float, float]]) -> Any:
    if code in "fd":
        if injections and rng.random() < 0.2:
            return injections[int(rng.integers(len(injections)))][1]
        return float(rng.normal(0.0, 10.0 ** rng.integers(-2, 3)))
    bits = struct.calcsize(code) * 8
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if code.islower() else (0, 2**bits - 1)
    return int(rng.integers(lo, hi, endpoint=True))


def _pack(fmt: str, value: Any) -> bytes:
    try:
        return struct.pack(fmt, value)
    except OverflowError:  # a float64 extreme into a float32 property
        return struct.pack(fmt, math.copysign(math.inf, value))


@st.composite
def ply_files(draw: Any) -> FileCase:
    """A PLY file: ascii or binary (both endians), scalar and list properties, then mutated."""
    fmt = draw(st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian"]))
    props: list[tuple[str, ...]] = [
        (name, draw(PLY_SCALARS))
        for name in _with_xyz(
            draw,
            draw(
                st.lists(
                    st.sampled_from(["x", "y", "z", "red", "green", "blue", "nx", "alpha"]),
                    max_size=6,
                    unique=True,
                )
            ),
        )
    ]
    if draw(chance(0.15)):
        props.insert(
            draw(st.integers(0, len(props))), ("neighbors", "list", draw(PLY_COUNT_TYPES), draw(PLY_SCALARS))
        )
    elements: list[tuple[str, int, list[tuple[str, ...]]]] = [("vertex", draw(st.integers(0, 30)), props)]
    face: list[tuple[str, ...]]
    if draw(chance(0.2)):
        elements.insert(0, ("camera", draw(st.integers(0, 2)), [("view_px", "float")]))
    if draw(chance(0.3)):
        face = [
            ("vertex_indices", "list", draw(PLY_COUNT_TYPES), draw(st.sampled_from(["int", "uint", "int32"])))
        ]
        elements.append(("face", draw(st.integers(0, 5)), face))
    rng = np.random.default_rng(draw(SEEDS))
    injections = draw(INJECTIONS)
    header = ["ply", f"format {fmt} 1.0", "comment fuzz"]
    for name, count, plist in elements:
        header.append(f"element {name} {count}")
        header += [
            f"property {' '.join(p[1:])} {p[0]}" if p[1] == "list" else f"property {p[1]} {p[0]}"
            for p in plist
        ]
    header.append("end_header")
    endian = "<" if fmt == "binary_little_endian" else ">"
    chunks: list[bytes] = []
    for _, count, plist in elements:
        for _ in range(count):
            values: list[tuple[str, Any]] = []
            for p in plist:
                if p[1] == "list":
                    k = int(rng.integers(0, 5))
                    values.append((PLY_TYPES[p[2]], k))
                    values += [
                        (PLY_TYPES[p[3]], _ply_value(rng, PLY_TYPES[p[3]], injections)) for _ in range(k)
                    ]
                else:
                    values.append((PLY_TYPES[p[1]], _ply_value(rng, PLY_TYPES[p[1]], injections)))
            if fmt == "ascii":
                chunks.append((" ".join(_float_text(v) for _, v in values) + "\n").encode())
            else:
                chunks.append(b"".join(_pack(endian + c, v) for c, v in values))
    body = b"".join(chunks)
    if fmt == "ascii" and draw(chance(0.3)):
        body = "\n".join(apply_line_ops(body.decode().split("\n"), draw(LINE_OPS))).encode()
    header = apply_line_ops(header, draw(LINE_OPS))
    data = ("\n".join(header) + "\n").encode() + apply_byte_ops(body, draw(BYTE_OPS))
    return FileCase("cloud.ply", data)


@st.composite
def bt_files(draw: Any) -> FileCase:
    """An OctoMap ``.bt``: a random occupancy tree (sometimes deeper than octomap's 16 levels), then mutated."""
    rng = np.random.default_rng(draw(SEEDS))
    chain = draw(st.one_of(st.integers(11, 15), st.integers(0, 17)))  # single-child levels above the leaves
    extra = draw(st.integers(1, 4))  # random levels below the chain
    p_child = draw(st.sampled_from([0.1, 0.25, 0.5]))
    records: list[bytes] = []
    n_children = 0

    def emit(depth: int) -> None:
        nonlocal n_children
        codes = [0] * 8
        if depth < chain:
            codes[int(rng.integers(8))] = 3
        else:
            for i in range(8):
                if rng.random() < p_child:
                    inner = depth + 1 < chain + extra and rng.random() < 0.5 and len(records) < 500
                    codes[i] = 3 if inner else int(rng.integers(1, 3))
        n_children += sum(c > 0 for c in codes)
        records.append(
            bytes(
                [
                    sum(c << 2 * i for i, c in enumerate(codes[:4])),
                    sum(c << 2 * i for i, c in enumerate(codes[4:])),
                ]
            )
        )
        for c in codes:
            if c == 3:
                emit(depth + 1)

    emit(0)
    good_res = st.sampled_from(["0.05", "0.1", "1", "0.01", "0.2"])
    res = draw(good_res if draw(chance(0.75)) else st.one_of(ANY_FLOATS.map(repr), TOKENS))
    header = [
        "# Octomap OcTree binary file",
        "# (feel free to add / change comments, but leave the first line as it is!)",
        "id OcTree",
        f"size {1 + n_children}",
        f"res {res}",
        "data",
    ]
    header = apply_line_ops(header, draw(LINE_OPS))
    data = ("\n".join(header) + "\n").encode() + apply_byte_ops(b"".join(records), draw(BYTE_OPS))
    return FileCase("map.bt", data)


NPY_DTYPES = ["<f8", "<f4", "<f2", ">f8", "<i4", "<i8", "|u1", "<u8", "|b1", "<c16", "<U3", "|S2", "|O", "xyz",
              "<M8[s]", "<m8[s]"]  # fmt: skip


@st.composite
def npy_files(draw: Any) -> FileCase:
    """A ``.npy`` of a random dtype and shape (object arrays pickled), header and data then mutated."""
    dtype = draw(st.one_of(st.sampled_from(["<f8", "<f4", "<i4", ">f8"]), st.sampled_from(NPY_DTYPES)))
    shape = draw(
        st.one_of(
            st.tuples(st.integers(1, 20), st.integers(3, 6)),
            st.tuples(st.integers(0, 20), st.integers(0, 6)),
            st.tuples(st.integers(0, 10)),
            st.just(()),
            st.tuples(st.integers(0, 4), st.integers(0, 4), st.integers(0, 4)),
        )
    )
    rng = np.random.default_rng(draw(SEEDS))
    size = int(np.prod(shape))
    if dtype == "|O":
        array = np.array([None, "a", 1.5, [1]] * size, dtype=object)[:size].reshape(shape)
    elif dtype == "xyz":
        array = np.zeros(shape, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    elif dtype in ("<U3", "|S2", "<M8[s]", "<m8[s]", "|b1", "<c16"):
        array = rng.integers(0, 100, size).astype(dtype).reshape(shape)
    else:
        array = np.asarray(_numbers(rng, np.dtype(dtype), size)).astype(dtype).reshape(shape)
        _inject(array, draw(INJECTIONS))
    if draw(st.booleans()):
        array = np.asfortranarray(array)
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    data = buf.getvalue()
    if draw(chance(0.3)):  # rewrite the header dict
        hlen = struct.unpack("<H", data[8:10])[0]
        text, body = data[10 : 10 + hlen].decode("latin-1"), data[10 + hlen :]
        key = draw(st.sampled_from(["descr", "shape", "fortran_order"]))
        value = draw(
            st.sampled_from(["'<f8'", "'>f4'", "'|O'", "'<U3'", "'|V8'", "'foo'", "[('x', '<f8')]", "(3, -1)",
                             "(99999999999, 3)", "()", "(18446744073709551616,)", "(2, 3)", "True", "1", "None", "{"])
        )  # fmt: skip
        pattern = {"descr": r"'descr': ('[^']*'|\[.*?\])", "shape": r"'shape': \([^)]*\)",
                   "fortran_order": r"'fortran_order': \w+"}[key]  # fmt: skip
        text = re.sub(pattern, lambda _: f"'{key}': {value}", text, count=1)
        version = draw(st.sampled_from([b"\x01\x00", b"\x01\x00", b"\x02\x00", b"\x09\x09"]))
        hl = struct.pack("<H", len(text)) if draw(chance(0.8)) else draw(st.binary(min_size=2, max_size=2))
        data = data[:6] + version + hl + text.encode("latin-1") + body
    data = apply_byte_ops(data, draw(BYTE_OPS))
    return FileCase("points.npy", data)


@st.composite
def xyz_files(draw: Any) -> FileCase:
    """XYZ text: rows of numbers with random separators, formats and comments, then mutated."""
    rng = np.random.default_rng(draw(SEEDS))
    n_cols = draw(st.sampled_from([3, 3, 3, 4, 6, 2, 1]))
    sep = draw(SEPARATORS)
    fmt = draw(st.sampled_from(["{:g}", "{!r}", "{:.3e}", "{:.0f}"]))
    rows = [
        sep.join(fmt.format(float(v)) for v in rng.normal(0, 5, n_cols))
        for _ in range(draw(st.integers(0, 30)))
    ]
    if draw(chance(0.3)):
        rows.insert(0, "# x y z")
    rows = apply_line_ops(rows, draw(LINE_OPS))
    text = "\n".join(rows) + draw(st.sampled_from(["\n", "", "\r\n"]))
    data = text.encode(draw(st.sampled_from(["utf-8", "utf-8", "utf-16"])))
    data = apply_byte_ops(data, draw(BYTE_OPS))
    return FileCase(draw(st.sampled_from(["points.xyz", "points.txt", "points.XYZ"])), data)


MAGICS = [b"", b"ply\n", b"ply\nformat ascii 1.0\n", b"# Octomap OcTree binary file\n", b"\x93NUMPY\x01\x00",
          b"VERSION .7\n", b"# .PCD v0.7\nFIELDS x y z\n", b"\x89HDF\r\n\x1a\n", b"\xef\xbb\xbf", b"\xff\xfe"]  # fmt: skip


@st.composite
def random_cloud_files(draw: Any) -> FileCase:
    """Random bytes behind a plausible magic, under every cloud suffix and a few unknown ones."""
    suffix = draw(
        st.sampled_from([".pcd", ".ply", ".npy", ".bt", ".xyz", ".txt", ".PLY", ".las", ".pcd.gz", ""])
    )
    data = draw(st.sampled_from(MAGICS)) + draw(st.binary(max_size=2048))
    return FileCase("cloud" + suffix, data)


# --- transforms ---


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@st.composite
def transform_texts(draw: Any) -> str:
    """What a user may pass as ``--transform``: an up vector, 16 numbers inline, or anything."""
    kind = draw(st.sampled_from(["up", "up", "tokens", "tokens", "matrix", "text", "digits"]))
    if kind == "up":
        return str(
            draw(SEPARATORS).join(
                repr(v)
                for v in draw(st.lists(st.one_of(st.floats(-2, 2), ANY_FLOATS), min_size=3, max_size=3))
            )
        )
    if kind == "tokens":
        return str(draw(SEPARATORS).join(draw(st.lists(NUMBER_TOKENS, max_size=5))))
    if kind == "matrix":  # a whole 4x4 typed inline instead of a file
        T = np.eye(4)
        rng = np.random.default_rng(draw(SEEDS))
        T[:3, :3], T[:3, 3] = _rotation(rng), rng.normal(0.0, 2.0, 3)
        return str(draw(SEPARATORS).join(repr(float(v)) for v in T.ravel()))
    if kind == "digits":
        return str(draw(st.text(alphabet="0123456789 .,-e", max_size=400)))
    return str(draw(st.one_of(st.text(max_size=40), st.text(max_size=12).map(lambda t: "~" + t))))


def _check_transform(T: np.ndarray, what: str) -> str | None:
    if T.shape != (4, 4) or not np.isfinite(T).all():
        return f"{what}: not a finite 4x4"
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > 1e-6
        or np.linalg.det(R) < 0
        or not np.allclose(T[3], [0, 0, 0, 1])
    ):
        return f"{what}: not a rigid transform"
    return None


def _transform_text(text: str, workdir: Path) -> str | None:
    from baseplace.terrain.io import load_transform

    T = load_transform(text)
    note = _check_transform(T, "up vector")
    if note:
        return note
    try:
        u = np.array([float(v) for v in text.replace(",", " ").split()])
    except ValueError:
        return None
    if u.shape == (3,) and np.isfinite(u).all():
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            m = np.abs(u).max()
            d = (u / m) / np.linalg.norm(u / m)
        if not np.allclose(T[:3, :3] @ d, [0.0, 0.0, 1.0], atol=1e-9):
            return f"up vector {text!r} is not mapped onto +z: R @ u = {T[:3, :3] @ d}"
    return None


@st.composite
def transform_files(draw: Any) -> FileCase:
    """A transform file: a rigid 4x4 in various layouts, perturbed, or random text/bytes."""
    kind = draw(st.sampled_from(["matrix", "matrix", "matrix", "text", "bytes"]))
    if kind == "matrix":
        rng = np.random.default_rng(draw(SEEDS))
        T = np.eye(4)
        T[:3, :3] = _rotation(rng) * draw(st.sampled_from([1.0, 1.0, 1.0, -1.0, 1.001, 1 + 1e-7]))
        T[:3, 3] = rng.normal(0, 3, 3)
        sep = draw(SEPARATORS)
        fmt = draw(st.sampled_from(["{!r}", "{:.17g}", "{:.6f}", "{:.3f}"]))
        rows = [sep.join(fmt.format(float(v)) for v in row) for row in T]
        if draw(st.booleans()):
            rows = ["[" + r + "]," for r in rows]
        if draw(chance(0.3)):
            rows.insert(0, "# T_world_sensor")
        text = "\n".join(apply_line_ops(rows, draw(LINE_OPS)))
        data = text.encode()
    elif kind == "text":
        data = draw(st.text(max_size=200)).encode()
    else:
        data = draw(st.binary(max_size=200))
    return FileCase("T.txt", apply_byte_ops(data, draw(BYTE_OPS)))


def _transform_file(case: FileCase, workdir: Path) -> str | None:
    from baseplace.terrain.io import load_transform

    path = workdir / case.name
    path.write_bytes(case.data)
    return _check_transform(load_transform(str(path)), "transform file")


# --------------------------------------------------------------------------------------------
# occupancy grids
# --------------------------------------------------------------------------------------------

IMAGE_MAGICS = [b"", b"\x89PNG\r\n\x1a\n", b"P5\n", b"P2\n", b"P6\n", b"BM", b"II*\x00", b"\xff\xd8\xff",
                b"RIFF\x00\x00\x00\x00WEBP", b"P7\n", b"PF\n", b"#?RADIANCE\n", b"GIF89a",
                b"\x00\x00\x00\x0cjP  \r\n\x87\n"]  # fmt: skip


@st.composite
def images(draw: Any) -> tuple[str, bytes]:
    """(suffix, bytes) of a map image: encoded by OpenCV or Pillow in random sizes/modes, or junk."""
    import cv2

    kind = draw(st.sampled_from(["cv2", "cv2", "pil", "pnm", "random"]))
    rng = np.random.default_rng(draw(SEEDS))
    h, w = draw(st.integers(1, 40)), draw(st.integers(1, 40))
    if kind == "cv2":
        ext = draw(st.sampled_from([".png", ".pgm", ".bmp"]))
        channels = 1 if ext == ".pgm" else draw(st.sampled_from([1, 3, 4]))
        dtype = np.uint16 if ext != ".bmp" and draw(chance(0.3)) else np.uint8
        top = int(np.iinfo(dtype).max)
        pixels = rng.choice([0, top // 2, top, int(rng.integers(0, top + 1))], size=(h, w, channels)).astype(
            dtype
        )
        ok, buf = cv2.imencode(ext, pixels)  # type: ignore[call-overload,arg-type,unused-ignore]
        data = buf.tobytes() if ok else b""
    elif kind == "pil":
        from PIL import Image

        mode = draw(st.sampled_from(["1", "L", "P", "LA", "RGB", "RGBA", "I;16", "I", "F"]))
        ext = draw(st.sampled_from([".png", ".bmp", ".pgm"]))
        out = io.BytesIO()
        try:
            img = Image.fromarray(rng.integers(0, 256, (h, w), dtype=np.uint8)).convert(mode)
            img.save(out, format={".png": "PNG", ".bmp": "BMP", ".pgm": "PPM"}[ext])
        except (OSError, ValueError, KeyError):
            out = io.BytesIO(b"")
        data = out.getvalue()
    elif kind == "pnm":  # a PNM header with odd numbers, then some data
        magic = draw(st.sampled_from(["P5", "P2", "P6", "P4", "P1"]))
        dims = [draw(st.one_of(st.integers(-2, 64), st.integers(0, 2**40), TOKENS)) for _ in range(3)]
        ext = ".pgm"
        data = f"{magic}\n{dims[0]} {dims[1]}\n{dims[2]}\n".encode() + draw(st.binary(max_size=256))
    else:
        ext = draw(st.sampled_from([".png", ".pgm", ".bmp"]))
        data = draw(st.sampled_from(IMAGE_MAGICS)) + draw(st.binary(max_size=512))
    data = apply_byte_ops(data, draw(BYTE_OPS))
    if draw(chance(0.1)):
        ext = draw(st.sampled_from([".png", ".pgm", ".bmp", ".PNG", ".jpg", ".tif", ""]))
    return ext, data


@dataclass(frozen=True)
class OccupancyCase:
    """A map YAML (text) and its image (file name, bytes)."""

    yaml_text: str
    image_name: str
    image: bytes

    def __repr__(self) -> str:
        return f"OccupancyCase(yaml_text={self.yaml_text!r}, image_name={self.image_name!r}, image={describe(self.image, 200)} [{len(self.image)} bytes])"


def _maybe(
    draw: Any,
    good: st.SearchStrategy[Any],
    odd: st.SearchStrategy[Any],
    p_good: float = 0.85,
    p_missing: float = 0.01,
) -> Any:
    """A good value (85 %), an odd one of the right kind (10 %), any YAML value, or the marker for a missing key."""
    roll = draw(st.integers(0, 999))
    if roll < p_good * 1000:
        return draw(good)
    if roll < (p_good + (1 - p_good) * 2 / 3) * 1000:
        return draw(odd)
    if roll < (1 - p_missing) * 1000:
        return draw(YAML_VALUES)
    return _MISSING


_MISSING = object()


@st.composite
def occupancy_cases(draw: Any) -> OccupancyCase:
    """A map_server YAML with valid or odd values for each key, and a valid or broken image."""
    ext, image = draw(images())
    name = "map" + ext
    odd_thresh = st.one_of(st.floats(-1, 2), NASTY_FLOATS)
    spec = {  # key: (good, odd)
        "image": (st.just(name), st.sampled_from(["missing.pgm", "", " ", ".", "map", "/", "x" * 300])),
        "resolution": (st.floats(0.001, 1), st.one_of(NASTY_FLOATS, st.integers(-1, 2))),
        "origin": (
            st.lists(st.floats(-100, 100), min_size=3, max_size=3),
            st.lists(st.one_of(st.floats(-100, 100), NASTY_FLOATS, st.booleans()), min_size=2, max_size=4),
        ),
        "negate": (st.sampled_from([0, 1, True, False]), st.sampled_from([2, -1, "yes", 0.5, "0"])),
        "occupied_thresh": (st.floats(0.5, 1), odd_thresh),
        "free_thresh": (st.floats(0, 0.49), odd_thresh),
        "mode": (
            st.sampled_from(["trinary", "scale", "raw", "Trinary", "RAW"]),
            st.sampled_from(["bogus", "", "1"]),
        ),
    }
    doc: dict[str, Any] = {}
    for key, (good, odd) in spec.items():
        value = _maybe(draw, good, odd, p_missing=0.3 if key == "mode" else 0.01)
        if value is not _MISSING:
            doc[key] = value
    if draw(chance(0.1)):
        doc[draw(st.text(max_size=6))] = draw(YAML_VALUES)
    style = draw(st.sampled_from(["dump"] * 5 + ["mutated", "mutated", "text", "nested", "tagged", "alias"]))
    if style == "text":
        text = draw(st.text(max_size=200))
    elif style == "alias":  # the other keys valid, one key a huge aliased list
        key = draw(st.sampled_from(["image", "origin", "negate", "mode"]))
        text = yaml.safe_dump({**_GOOD_MAP, "image": name, key: None}) + alias_bomb(draw(ALIAS_LEVELS), key)
        text = "\n".join(line for line in text.split("\n") if line != f"{key}: null")
    elif style == "nested":
        text = "image: " + draw(DEEP_NESTING) + "\n"
    elif style == "tagged":
        text = draw(
            st.sampled_from(["!!python/object/apply:os.getcwd []", "image: !!binary aGVsbG8=\n", "a: &a [1]\nb: *b\n",
                             "--- 1\n--- 2\n", "image: 2001-12-14\nresolution: !!float 0.1\n", "? [a]\n: 1\n"])
        )  # fmt: skip
    else:
        text = yaml.safe_dump(
            doc, default_flow_style=draw(st.sampled_from([None, True, False])), allow_unicode=True
        )
        if style == "mutated":
            text = "\n".join(apply_line_ops(text.split("\n"), draw(LINE_OPS)))
    return OccupancyCase(text, name, image)


_GOOD_MAP = {
    "resolution": 0.1,
    "origin": [0.0, 0.0, 0.0],
    "negate": 0,
    "occupied_thresh": 0.65,
    "free_thresh": 0.2,
}


def _load_occupancy(case: OccupancyCase, workdir: Path) -> str | None:
    from baseplace.world.occupancy import load_occupancy

    (workdir / "map.yaml").write_text(case.yaml_text, encoding="utf-8", errors="surrogatepass")
    if case.image_name:
        (workdir / case.image_name).write_bytes(case.image)
    grid = load_occupancy(workdir / "map.yaml")
    values = set(np.unique(grid.data).tolist())
    if not values <= set(range(-1, 101)):
        return f"cell values outside -1..100: {sorted(values - set(range(-1, 101)))[:5]}"
    if not (math.isfinite(grid.resolution) and grid.resolution > 0 and all(map(math.isfinite, grid.origin))):
        return "non-finite resolution or origin"
    return None


# --------------------------------------------------------------------------------------------
# reachability and surface maps (HDF5)
# --------------------------------------------------------------------------------------------


def prepare(target: str) -> None:
    """Build what a target's cases share (the reference map files: a map build, compiled on first use)
    before any case runs, outside the per-case time limit."""
    if target.startswith(("rmap", "smap")):
        reference_files()


@cache
def reference_files() -> dict[str, bytes]:
    """Bytes of a small real reachability map and surface map of the planar3 test robot."""
    import tempfile

    from baseplace.placement.surface_map import build_surface_map
    from baseplace.placement.surface_storage import save_surface_map
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.storage import save_map
    from baseplace.robots.model import Robot

    robot = Robot(DATA / "planar3.toml")
    rmap = build_map(robot, None, BuildSettings(samples=20_000, seed=1, manipulability=True))
    rmap = dataclasses.replace(
        rmap, info=dataclasses.replace(rmap.info, build_time_s=0.0)
    )  # same bytes every time
    smap = build_surface_map(
        robot, {"arm": rmap}, "0.5,-0.2;0.9,-0.2;0.9,0.2;0.5,0.2", 0.4, resolution=0.1, orientations=4
    )
    with tempfile.TemporaryDirectory() as tmp:
        save_map(rmap, Path(tmp) / "m.rmap")
        save_surface_map(smap, Path(tmp) / "s.h5")
        return {"rmap": (Path(tmp) / "m.rmap").read_bytes(), "smap": (Path(tmp) / "s.h5").read_bytes()}


TEXTS = {"rmap": ("grid", "info"), "smap": ("meta",)}
"""The JSON texts of each file kind, in the order the checksum takes them (format version 2)."""


@cache
def reference_contents(kind: str) -> tuple[dict[str, Any], dict[str, str], dict[str, np.ndarray]]:
    """(attributes, texts, other datasets) of a reference file."""
    with h5py.File(io.BytesIO(reference_files()[kind]), "r") as f:
        texts = {k: bytes(f[k][()]).decode() for k in TEXTS[kind]}
        return dict(f.attrs), texts, {k: f[k][()] for k in f if k not in texts}


@dataclass(frozen=True)
class BytesCase:
    """Mutations of a reference file (or random bytes instead of it)."""

    ops: tuple[tuple[Any, ...], ...]
    random: bytes | None = None


def bytes_cases() -> st.SearchStrategy[BytesCase]:
    """Byte mutations of the reference file (1-8, mostly in its first 4 KiB), or random bytes."""
    mutated = st.lists(_BYTE_OP, min_size=1, max_size=8).map(lambda ops: BytesCase(tuple(ops)))
    random = st.tuples(st.sampled_from([b"", b"\x89HDF\r\n\x1a\n"]), st.binary(max_size=2048)).map(
        lambda t: BytesCase((), t[0] + t[1])
    )
    return st.one_of(mutated, mutated, mutated, random)


def _loader(kind: str) -> Callable[[Path], Any]:
    if kind == "rmap":
        from baseplace.reachability.storage import load_map

        return load_map
    from baseplace.placement.surface_storage import load_surface_map

    return load_surface_map


def _check_loaded_map(kind: str, m: Any) -> str | None:
    if kind == "rmap":
        n_cells = m.grid.n_voxels * m.grid.n_orientations
        cells = np.asarray(m.cells)
        if len(cells) != len(m.counts) or (
            m.manipulability is not None and len(m.manipulability) != len(cells)
        ):
            return "cells, counts and manipulability differ in length"
        if len(cells) and (cells.min() < 0 or cells.max() >= n_cells or np.any(np.diff(cells) <= 0)):
            return "cells are not sorted, unique flat indices inside the grid"
        if not all(math.isfinite(v) for v in m.grid.origin):
            return "non-finite grid origin"
        return None
    values = np.asarray(m.values)
    if values.ndim != 3 or 0 in values.shape:
        return f"values have shape {values.shape}, not (T, NX, NY)"
    if not (np.isfinite(values).all() and values.min() >= 0 and values.max() <= 1):
        return "values outside [0, 1]"
    polygon = np.asarray(m.polygon)
    if polygon.ndim != 2 or polygon.shape[1:] != (2,) or not np.isfinite(polygon).all():
        return "polygon is not finite (N, 2)"
    if not (math.isfinite(m.resolution) and m.resolution > 0 and all(map(math.isfinite, m.origin))):
        return "non-finite or non-positive resolution or origin"
    return None


def _run_bytes(kind: str) -> Callable[[BytesCase, Path], str | None]:
    def run(case: BytesCase, workdir: Path) -> str | None:
        path = workdir / ("m.rmap" if kind == "rmap" else "s.h5")
        data = (
            case.random
            if case.random is not None
            else apply_byte_ops(reference_files()[kind], list(case.ops))
        )
        path.write_bytes(data)
        return _check_loaded_map(kind, _loader(kind)(path))

    return run


# structured HDF5: the right `format`, each attribute and dataset kept, dropped or replaced

JSON_VALUES = YAML_VALUES
ODD_ATTRS = st.one_of(
    st.sampled_from([0, -1, 2, 2**62, 1.5, "1", "x", "", b"1", True, math.nan]),
    st.builds(lambda n: np.arange(n), st.integers(0, 3)),
)
GRID_FIELDS: dict[str, st.SearchStrategy[Any]] = {
    "origin": st.lists(st.one_of(st.floats(-2, 2), NASTY_FLOATS), min_size=0, max_size=4),
    "voxel_size": st.one_of(st.floats(0.01, 0.5), NASTY_FLOATS, st.integers(-1, 1)),
    "shape": st.lists(st.one_of(st.integers(-2, 40), st.integers(0, 2**40)), min_size=0, max_size=4),
    "nside": st.one_of(st.integers(-1, 8), st.sampled_from([64, 300, 2**20, 2**40])),
    "n_twist": st.one_of(st.integers(-1, 16), st.integers(0, 2**40)),
}
INFO_FIELDS: dict[str, st.SearchStrategy[Any]] = {
    "robot": st.sampled_from(["planar3", ""]),
    "urdf_sha256": st.sampled_from(["0" * 64, ""]),
    "arm": st.sampled_from(["arm", "left"]),
    "joint_names": st.lists(st.sampled_from(["lift", "joint1", "x"]), max_size=4),
    "base_frame": st.just("base_link"),
    "tcp_frame": st.just("tool0"),
    "samples": st.integers(-1, 10**6),
    "seed": st.integers(-1, 10),
    "build_time_s": st.floats(0, 10),
    "self_collision": st.booleans(),
    "dropped_self_collision": st.integers(0, 10),
}
META_FIELDS: dict[str, st.SearchStrategy[Any]] = {
    "shape": GRID_FIELDS["shape"].map(lambda s: [min(int(v), 2**31) for v in s]),
    "origin": GRID_FIELDS["origin"],
    "resolution": GRID_FIELDS["voxel_size"],
    "polygon": st.lists(st.lists(st.one_of(st.floats(-2, 2), NASTY_FLOATS), max_size=3), max_size=5),
    "height": st.one_of(st.floats(0, 2), NASTY_FLOATS),
    "robot": st.sampled_from(["planar3", ""]),
    "arms": st.lists(st.sampled_from(["arm", "left"]), max_size=2),
    "combine": st.sampled_from(["any", "both", "bogus"]),
    "cone": st.one_of(st.none(), st.floats(0, 4), NASTY_FLOATS),
    "tcp_height": st.one_of(st.floats(0, 0.2), NASTY_FLOATS),
}


@dataclass(frozen=True)
class H5Case:
    """A map file written from parts: attributes, texts and datasets, each possibly missing or odd."""

    attrs: dict[str, Any]
    texts: dict[str, Any]
    texts_as: str  # "datasets" (format version 2) or "attributes" (version 1)
    datasets: dict[str, Any]
    digest: str  # "right" (as the loader computes it for the stored version), "wrong" or "missing"

    def __repr__(self) -> str:
        return (
            f"H5Case(attrs={describe(self.attrs, 600)}, texts={describe(self.texts, 600)}, "
            f"texts_as={self.texts_as!r}, datasets={describe(self.datasets, 600)}, digest={self.digest!r})"
        )


@st.composite
def _json_attr(draw: Any, reference: str, fields: dict[str, st.SearchStrategy[Any]]) -> Any:
    """A JSON attribute: the reference dict with fields kept/dropped/replaced, or something else."""
    roll = draw(st.integers(0, 99))
    if roll < 75:
        doc = json.loads(reference)
        for key, valid in fields.items():
            action = draw(st.integers(0, 19))
            if action < 13:
                continue
            if action < 16:
                doc[key] = draw(valid)
            elif action < 18:
                doc[key] = draw(JSON_VALUES)
            else:
                doc.pop(key, None)
        if draw(chance(0.05)):
            doc[draw(st.text(max_size=5))] = draw(JSON_VALUES)
        return json.dumps(doc)
    if roll < 85:
        return json.dumps(draw(JSON_VALUES))
    if roll < 90:
        return draw(st.sampled_from(["", "{", "[" * 3000 + "]" * 3000, "null", '{"a": 1}']))
    if roll < 95:
        return draw(ODD_ATTRS)
    return _MISSING


@st.composite
def _dataset(draw: Any, reference: np.ndarray) -> Any:
    roll = draw(st.integers(0, 99))
    if roll < 70:
        return reference
    if roll < 80:
        lo, hi = sorted(draw(st.tuples(st.integers(0, len(reference)), st.integers(0, len(reference)))))
        return reference[lo:hi]
    if roll < 85:
        return reference.astype(draw(st.sampled_from(["<f8", "<i4", "<u8", "<f2", "|u1", "<i8"])))
    if roll < 90:
        rng = np.random.default_rng(draw(SEEDS))
        return rng.integers(-(2**40), 2**40, size=draw(st.integers(0, 50)))
    if roll < 93:
        return np.zeros(draw(st.sampled_from([(2, 3), (), (0,), (1, 1, 1)])))
    if roll < 95:
        return np.array([b"ab", b"c"])
    if roll < 97:
        return np.zeros(3, dtype=[("a", "<f8"), ("b", "<i4")])
    return _MISSING


def h5_cases(kind: str) -> st.SearchStrategy[H5Case]:
    """A file with the right ``format`` attribute (mostly) and kept, dropped or odd contents."""

    @st.composite
    def build(draw: Any) -> H5Case:
        attrs_ref, texts_ref, sets_ref = reference_contents(kind)
        attrs: dict[str, Any] = {}
        fmt = attrs_ref["format"]  # fixed-length bytes; version 1 wrote a str
        attrs["format"] = draw(
            st.one_of(
                st.just(fmt), st.just(fmt), st.just(fmt), st.just(fmt.decode()), ODD_ATTRS, st.just(_MISSING)
            )
        )
        attrs["format_version"] = draw(
            st.one_of(st.just(2), st.just(2), st.just(2), st.just(1), ODD_ATTRS, st.just(_MISSING))
        )
        json_fields: dict[str, dict[str, st.SearchStrategy[Any]]]
        json_fields = {"grid": GRID_FIELDS, "info": INFO_FIELDS} if kind == "rmap" else {"meta": META_FIELDS}
        texts = {name: draw(_json_attr(texts_ref[name], fields)) for name, fields in json_fields.items()}
        datasets = {name: draw(_dataset(ref)) for name, ref in sets_ref.items()}
        digest = draw(st.sampled_from(["right", "right", "right", "right", "wrong", "missing"]))
        return H5Case(
            {k: v for k, v in attrs.items() if v is not _MISSING},
            {k: v for k, v in texts.items() if v is not _MISSING},
            draw(st.sampled_from(["datasets", "datasets", "datasets", "attributes"])),
            {k: v for k, v in datasets.items() if v is not _MISSING},
            digest,
        )

    return build()


def _run_h5(kind: str) -> Callable[[H5Case, Path], str | None]:
    def run(case: H5Case, workdir: Path) -> str | None:
        path = workdir / ("m.rmap" if kind == "rmap" else "s.h5")
        with h5py.File(path, "w") as f:
            for key, value in case.attrs.items():
                f.attrs[key] = value
            for key, value in case.texts.items():
                if case.texts_as == "attributes":
                    f.attrs[key] = value
                elif isinstance(value, str):
                    f.create_dataset(key, data=np.frombuffer(value.encode(), dtype=np.uint8))
                else:
                    f.create_dataset(key, data=value)
            for key, value in case.datasets.items():
                f.create_dataset(key, data=value)
            h = hashlib.sha256()
            if case.texts_as == "datasets" and type(case.attrs.get("format_version")) is int:
                for key in TEXTS[kind]:
                    if key in f:
                        h.update(np.ascontiguousarray(f[key][()]).tobytes())
            for key in case.datasets:
                h.update(np.ascontiguousarray(f[key][()]).tobytes())
            if case.digest == "right":
                f.attrs["sha256"] = np.bytes_(h.hexdigest().encode())
            elif case.digest == "wrong":
                f.attrs["sha256"] = "0" * 64
        return _check_loaded_map(kind, _loader(kind)(path))

    return run


# --------------------------------------------------------------------------------------------
# robot specs and URDFs
# --------------------------------------------------------------------------------------------

JOINTS = ["lift", "joint1", "joint2", "joint3", "tool_joint", "nope", ""]
FRAMES = ["tool0", "link3", "link2", "base_link", "lift_link", "nope", ""]
PATH_TEXT = st.one_of(
    st.sampled_from(
        [str(DATA / "planar3.urdf"), "planar3.urdf", "missing.urdf", "", ".", str(DATA / "broken.urdf"),
         str(DATA / "missing_link.urdf"), str(DATA), "/dev/null", "\x00"]
    ),
    st.text(max_size=10),
    st.text(alphabet="ab/._~", min_size=200, max_size=300),
)  # fmt: skip


def _robot_fields() -> dict[str, tuple[st.SearchStrategy[Any], st.SearchStrategy[Any]]]:
    """Robot spec keys: (good values, odd values of the right kind)."""
    planar3_arm = {"joints": ["lift", "joint1", "joint2", "joint3"], "tcp_frame": "tool0"}
    some_arm = st.fixed_dictionaries(
        {"joints": st.lists(st.sampled_from(JOINTS), max_size=5), "tcp_frame": st.sampled_from(FRAMES)}
    )
    polygon = st.lists(
        st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)).map(list), min_size=3, max_size=6
    )
    odd_polygon = st.lists(
        st.lists(st.one_of(st.floats(-1, 1), NASTY_FLOATS, st.text(max_size=2)), min_size=1, max_size=3),
        max_size=6,
    )
    return {
        "name": (st.sampled_from(["planar3", "fuzz"]), st.text(max_size=8)),
        "urdf": (st.just(str(DATA / "planar3.urdf")), PATH_TEXT),
        "base_frame": (st.just("base_link"), st.sampled_from(FRAMES)),
        "footprint": (
            st.one_of(
                st.fixed_dictionaries({"radius": st.floats(0.01, 1)}),
                st.fixed_dictionaries({"polygon": polygon}),
            ),
            st.one_of(
                st.fixed_dictionaries(
                    {"radius": st.one_of(st.floats(-1, 6), NASTY_FLOATS, st.text(max_size=3))}
                ),
                st.fixed_dictionaries({"polygon": odd_polygon}),
                st.dictionaries(st.sampled_from(["radius", "polygon", "x"]), YAML_VALUES, max_size=2),
            ),
        ),
        "arms": (
            st.one_of(
                st.just({"arm": planar3_arm}),
                st.dictionaries(st.sampled_from(["arm", "left"]), some_arm, min_size=1, max_size=2),
            ),
            st.dictionaries(st.text(max_size=4), st.one_of(some_arm, YAML_VALUES), max_size=3),
        ),
        "default_arm": (st.just("arm"), st.sampled_from(["left", "nope", ""])),
        "joint_limits": (
            st.dictionaries(
                st.sampled_from(JOINTS[:4]),
                st.tuples(st.floats(-3, 0), st.floats(0.1, 3)).map(list),
                max_size=3,
            ),
            st.dictionaries(
                st.sampled_from(JOINTS),
                st.lists(st.one_of(st.floats(-3, 3), NASTY_FLOATS), max_size=3),
                max_size=3,
            ),
        ),
        "reference": (
            st.dictionaries(st.sampled_from(JOINTS[:5]), st.floats(-1, 1), max_size=3),
            st.dictionaries(
                st.sampled_from(JOINTS), st.one_of(NASTY_FLOATS, st.text(max_size=2)), max_size=3
            ),
        ),
        "package_dirs": (
            st.lists(st.just(str(DATA)), max_size=2),
            st.lists(st.sampled_from([".", "nope", "", str(DATA / "planar3.urdf")]), max_size=3),
        ),
        "srdf": (st.just(""), st.sampled_from(["nope.srdf", str(DATA / "planar3.urdf")])),
    }


REQUIRED_ROBOT_KEYS = ("name", "urdf", "base_frame", "footprint", "arms")


@st.composite
def robot_dicts(draw: Any) -> dict[str, Any]:
    """A robot spec table: each key good, odd or missing; optional keys sometimes present."""
    doc: dict[str, Any] = {}
    for key, (good, odd) in _robot_fields().items():
        required = key in REQUIRED_ROBOT_KEYS
        if not required and draw(chance(0.6)):
            continue
        value = _maybe(draw, good, odd, p_missing=0.01 if required else 0.0)
        if value is not _MISSING:
            doc[key] = value
    if draw(chance(0.03)):
        doc[draw(st.text(max_size=6))] = draw(YAML_VALUES)
    return doc


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v if x is not None) + "]"
    if isinstance(v, dict):
        items = (
            f"{json.dumps(str(k), ensure_ascii=False)} = {_toml_value(x)}"
            for k, x in v.items()
            if x is not None
        )
        return "{ " + ", ".join(items) + " }"
    return json.dumps(str(v))


def to_toml(doc: dict[str, Any]) -> str:
    """A TOML document of ``doc`` (inline tables and arrays; None values are left out)."""
    return "".join(
        f"{json.dumps(str(k), ensure_ascii=False)} = {_toml_value(v)}\n"
        for k, v in doc.items()
        if v is not None
    )


def _check_robot(robot: Any) -> str | None:
    spec = robot.spec
    longest = max(len(spec.name), len(spec.base_frame), len(spec.default_arm))
    if longest > 1000:
        return f"a name of {longest} chars accepted"
    if spec.footprint_polygon is not None and not np.isfinite(np.asarray(spec.footprint_polygon)).all():
        return "non-finite footprint polygon accepted"
    if not all(math.isfinite(v) for v in spec.reference.values()):
        return "non-finite reference joint value accepted"
    for name in spec.arms:
        arm = robot.arm(name)
        arrays = (arm.lower, arm.upper, arm.placements, arm.axes, arm.T_last_tcp)
        if not all(np.isfinite(a).all() for a in arrays):
            return f"arm {name!r} has non-finite kinematics"
    return None


def _spec_dict(doc: dict[str, Any], workdir: Path) -> str | None:
    from baseplace.robots.model import Robot
    from baseplace.robots.spec import spec_from_dict

    return _check_robot(Robot(spec_from_dict(doc, DATA, "fuzz spec")))


@st.composite
def robot_files(draw: Any) -> FileCase:
    """A robot spec file: TOML or YAML of :func:`robot_dicts`, maybe mutated, or junk text."""
    suffix = draw(st.sampled_from([".toml", ".toml", ".yaml", ".yml", ".TOML", ".json"]))
    yaml_file = "toml" not in suffix.lower()
    style = draw(
        st.sampled_from(["dump", "dump", "mutated", "text", "nested", *(["alias"] if yaml_file else [])])
    )
    if style == "text":
        text = draw(st.text(max_size=200))
    elif style == "alias":  # a good spec but one value a huge aliased list
        key = draw(st.sampled_from(["name", "base_frame", "default_arm"]))
        good = {"name": "fuzz", "urdf": str(DATA / "planar3.urdf"), "base_frame": "base_link",
                "footprint": {"radius": 0.3}, "arms": {"arm": {"joints": ["joint1"], "tcp_frame": "tool0"}}}  # fmt: skip
        good.pop(key, None)
        text = yaml.safe_dump(good) + alias_bomb(draw(ALIAS_LEVELS), key)
    elif style == "nested":
        text = "name = " + draw(DEEP_NESTING) if "toml" in suffix.lower() else "name: " + draw(DEEP_NESTING)
    else:
        doc = draw(robot_dicts())
        text = to_toml(doc) if "toml" in suffix.lower() else yaml.safe_dump(doc, allow_unicode=True)
        if style == "mutated":
            text = "\n".join(apply_line_ops(text.split("\n"), draw(LINE_OPS)))
    return FileCase("robot" + suffix, text.encode("utf-8", "surrogatepass"))


def _spec_file(case: FileCase, workdir: Path) -> str | None:
    from baseplace.robots.model import Robot

    path = workdir / case.name
    path.write_bytes(case.data)
    return _check_robot(Robot(path))


URDF_VALUES = st.one_of(
    st.sampled_from(["0 0 0", "0 0 1", "1 0 0", "nan 0 0", "inf 0 0", "1e999 1 1", "", "abc", "0 0", "1 2 3 4", "-1",
                     "revolute", "continuous", "prismatic", "fixed", "floating", "planar", "spherical", "base_link",
                     "link1", "link2", "link3", "tool0", "lift_link", "joint1", "lift"]),
    TOKENS,
    st.lists(ANY_FLOATS, min_size=1, max_size=4).map(lambda v: " ".join(map(repr, v))),
)  # fmt: skip
URDF_OPS = st.lists(
    st.one_of(
        st.tuples(st.just("attr"), _INDEX, URDF_VALUES),
        st.tuples(st.just("lines"), LINE_OPS),
        st.tuples(st.just("bytes"), BYTE_OPS),
    ),
    max_size=3,
)


@dataclass(frozen=True)
class UrdfCase:
    """Mutations of ``tests/data/planar3.urdf`` and the arm joints/TCP asked of it."""

    ops: tuple[tuple[Any, ...], ...]
    joints: tuple[str, ...]
    tcp_frame: str


def urdf_cases() -> st.SearchStrategy[UrdfCase]:
    """Attribute, line and byte mutations of a valid URDF, loaded as a robot with one arm."""
    return st.builds(
        UrdfCase,
        URDF_OPS.map(tuple),
        st.one_of(
            st.just(("lift", "joint1", "joint2", "joint3")),
            st.lists(st.sampled_from(JOINTS[:5]), min_size=1, max_size=4, unique=True).map(tuple),
        ),
        st.sampled_from(["tool0", "tool0", "tool0", "link3", "base_link"]),
    )


def mutate_urdf(ops: tuple[tuple[Any, ...], ...]) -> bytes:
    """The planar3 URDF with ``ops`` applied."""
    text = (DATA / "planar3.urdf").read_text()
    data = b""
    for op in ops:
        if op[0] == "attr":
            matches = list(re.finditer(r'(\w+)="([^"]*)"', text))
            if matches:
                m = matches[op[1] % len(matches)]
                text = text[: m.start(2)] + op[2].replace('"', "&quot;") + text[m.end(2) :]
        elif op[0] == "lines":
            text = "\n".join(apply_line_ops(text.split("\n"), op[1]))
    data = text.encode("utf-8", "surrogatepass")
    for op in ops:
        if op[0] == "bytes":
            data = apply_byte_ops(data, op[1])
    return data


def _urdf(case: UrdfCase, workdir: Path) -> str | None:
    from baseplace.robots.model import Robot
    from baseplace.robots.spec import ArmSpec, RobotSpec

    path = workdir / "robot.urdf"
    path.write_bytes(mutate_urdf(case.ops))
    spec = RobotSpec(
        "fuzz", path, "base_link", {"arm": ArmSpec(case.joints, case.tcp_frame)}, "arm", footprint_radius=0.25
    )
    return _check_robot(Robot(spec))


# --------------------------------------------------------------------------------------------
# pose parsing and pose math
# --------------------------------------------------------------------------------------------


@st.composite
def pose_texts(draw: Any) -> tuple[str, str]:
    """(parser, text): number-like tokens with odd separators, or any text."""
    which = draw(st.sampled_from(["pose6", "base"]))
    if draw(chance(0.8)):
        n = draw(st.one_of(st.just(6 if which == "pose6" else 3), st.integers(0, 8)))
        text = draw(SEPARATORS).join(draw(st.lists(NUMBER_TOKENS, min_size=n, max_size=n)))
    else:
        text = draw(st.text(max_size=60))
    return which, text


def _parse_pose(case: tuple[str, str], workdir: Path) -> str | None:
    from baseplace.geometry.poses import parse_base_pose, parse_pose6

    which, text = case
    if which == "base":
        p = parse_base_pose(text)
        return None if all(map(math.isfinite, (p.x, p.y, p.yaw))) else "non-finite base pose"
    return _check_transform(parse_pose6(text), "pose")


@st.composite
def polygon_inputs(draw: Any) -> Any:
    """A polygon as text ``"x1,y1;..."`` (valid, perturbed or junk) or as (ragged) arrays."""
    kind = draw(st.sampled_from(["star", "star", "tokens", "text", "lists", "array"]))
    if kind == "star":  # vertices sorted by angle: a simple polygon, then perturbed
        rng = np.random.default_rng(draw(SEEDS))
        n = draw(st.integers(1, 8))
        angles = np.sort(rng.uniform(0, 2 * np.pi, n))
        radii = rng.uniform(0.1, 2.0, n) * 10.0 ** draw(st.integers(-8, 8))
        rows = [f"{r * math.cos(a):g},{r * math.sin(a):g}" for a, r in zip(angles, radii, strict=True)]
        return ";".join(apply_line_ops(rows, draw(LINE_OPS)))
    if kind == "tokens":
        vertices = draw(st.lists(st.lists(NUMBER_TOKENS, max_size=3).map(",".join), max_size=8))
        return draw(st.sampled_from([";", "; ", ";;"])).join(vertices) + draw(st.sampled_from(["", ";", " "]))
    if kind == "text":
        return draw(st.text(max_size=60))
    if kind == "lists":
        return draw(st.lists(st.lists(st.one_of(ANY_FLOATS, st.integers(-5, 5)), max_size=3), max_size=8))
    shape = draw(st.sampled_from([(4, 2), (3, 2), (2, 2), (4, 3), (0, 2), (4,), (2, 2, 2), ()]))
    arr = np.random.default_rng(draw(SEEDS)).normal(size=shape)
    _inject(arr, draw(INJECTIONS))
    return arr


def _parse_polygon(case: Any, workdir: Path) -> str | None:
    import shapely

    from baseplace.placement.surface_map import parse_polygon

    pts = parse_polygon(case)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.isfinite(pts).all():
        return "not >= 3 finite (x, y) vertices"
    with np.errstate(all="ignore"):
        area = shapely.Polygon(pts).area
    return None if math.isfinite(area) and area > 0 else f"polygon of area {area} accepted"


ANGLES = st.floats(-math.pi, math.pi)


@st.composite
def rpy_batches(draw: Any) -> tuple[list[float], list[float], list[float]]:
    """Angles (roll, pitch, yaw) away from gimbal lock (|cos pitch| > 1e-3), some far outside [-pi, pi]."""
    wide = st.floats(-1e3, 1e3)
    n = draw(st.integers(1, 5))
    rolls = draw(st.lists(st.one_of(ANGLES, wide), min_size=n, max_size=n))
    yaws = draw(st.lists(st.one_of(ANGLES, wide), min_size=n, max_size=n))
    pitches = draw(
        st.lists(
            st.one_of(st.floats(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3), wide), min_size=n, max_size=n
        ).filter(lambda ps: all(abs(math.cos(p)) > 1e-3 for p in ps))
    )
    return rolls, pitches, yaws


def _prop_rpy(case: tuple[list[float], list[float], list[float]], workdir: Path) -> None:
    from baseplace.geometry.poses import matrix_to_rpy, rpy_to_matrix

    r, p, y = (np.asarray(v) for v in case)
    R = rpy_to_matrix(r, p, y)
    assert R.shape == (len(r), 3, 3)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12), "rpy_to_matrix is not orthonormal"
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12), "rpy_to_matrix det != 1"
    back = matrix_to_rpy(R)
    assert back.shape == (len(r), 3)
    assert np.all(np.abs(back[:, 1]) <= math.pi / 2 + 1e-12) and np.all(
        np.abs(back[:, [0, 2]]) <= math.pi + 1e-12
    )
    R2 = rpy_to_matrix(back[:, 0], back[:, 1], back[:, 2])
    assert np.allclose(R2, R, atol=1e-9), (
        f"rpy -> matrix -> rpy -> matrix differs by {np.abs(R2 - R).max():.3g}"
    )
    for i in range(len(r)):  # scalar calls agree with the batch
        assert np.allclose(rpy_to_matrix(r[i], p[i], y[i]), R[i], atol=1e-15, rtol=0)
        assert np.allclose(matrix_to_rpy(R[i]), back[i], atol=1e-12, rtol=0)


@st.composite
def rigid_transforms(draw: Any) -> np.ndarray:
    """(N, 4, 4) rigid transforms from random unit quaternions and translations up to 1e3 m, or one (4, 4)."""
    n = draw(st.integers(0, 4))
    out = []
    for _ in range(max(n, 1)):
        q = draw(st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1))
        q = np.asarray(q) / np.linalg.norm(q)
        w, x, y, z = q
        T = np.eye(4)
        T[:3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
        T[:3, 3] = draw(st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3))
        out.append(T)
    return np.stack(out) if n else out[0]


def _prop_invert(T: np.ndarray, workdir: Path) -> None:
    from baseplace.geometry.poses import invert_transforms

    inv = invert_transforms(T)
    assert inv.shape == T.shape
    scale = max(1.0, float(np.abs(T[..., :3, 3]).max()))
    eye = np.broadcast_to(np.eye(4), T.shape)
    assert np.allclose(inv @ T, eye, atol=1e-12 * scale), f"inv @ T != I by {np.abs(inv @ T - eye).max():.3g}"
    assert np.allclose(T @ inv, eye, atol=1e-12 * scale), f"T @ inv != I by {np.abs(T @ inv - eye).max():.3g}"
    assert np.allclose(invert_transforms(inv), T, atol=1e-12 * scale), "inverting twice is not the identity"
    assert np.allclose(inv, np.linalg.inv(T), atol=1e-9 * scale), "differs from the general inverse"


BASE_POSES = st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4), st.floats(-50, 50))


def _prop_basepose(case: tuple[float, float, float], workdir: Path) -> None:
    from baseplace.geometry.poses import BasePose

    x, y, yaw = case
    pose = BasePose(x, y, yaw)
    T = pose.matrix()
    back = BasePose.from_matrix(T)
    assert back.x == x and back.y == y, "from_matrix changed x or y"
    assert -math.pi <= back.yaw <= math.pi
    d = math.remainder(back.yaw - yaw, 2 * math.pi)
    assert abs(d) < 1e-12 * max(1.0, abs(yaw)), f"yaw {yaw} came back as {back.yaw}"
    assert np.allclose(back.matrix(), T, atol=1e-12), "matrix -> from_matrix -> matrix differs"
    assert np.allclose(BasePose.batch_matrix([case])[0], T, atol=1e-15), "batch_matrix differs from matrix"
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12) and T[2, 3] == 0.0


# --------------------------------------------------------------------------------------------
# the targets
# --------------------------------------------------------------------------------------------

TARGETS: dict[str, Target] = {
    t.name: t
    for t in [
        Target(
            "cloud_pcd", pcd_files(), _load_cloud, ci_examples=150, doc="PCD ascii/binary/compressed, mutated"
        ),
        Target("cloud_ply", ply_files(), _load_cloud, ci_examples=150, doc="PLY ascii/binary LE/BE, mutated"),
        Target("cloud_bt", bt_files(), _load_cloud, ci_examples=150, doc="OctoMap .bt trees, mutated"),
        Target(
            "cloud_npy", npy_files(), _load_cloud, ci_examples=150, doc=".npy of any dtype/shape, mutated"
        ),
        Target("cloud_xyz", xyz_files(), _load_cloud, ci_examples=150, doc="XYZ/TXT text, mutated"),
        Target(
            "cloud_random", random_cloud_files(), _load_cloud, ci_examples=150, doc="random bytes, any suffix"
        ),
        Target(
            "transform_text", transform_texts(), _transform_text, ci_examples=200, doc="load_transform(text)"
        ),
        Target(
            "transform_file", transform_files(), _transform_file, ci_examples=150, doc="load_transform(file)"
        ),
        Target("occupancy", occupancy_cases(), _load_occupancy, ci_examples=150, doc="map YAML + image"),
        Target(
            "rmap_bytes", bytes_cases(), _run_bytes("rmap"), ci_examples=150, doc="load_map, mutated bytes"
        ),
        Target(
            "rmap_h5", h5_cases("rmap"), _run_h5("rmap"), ci_examples=120, doc="load_map, odd HDF5 contents"
        ),
        Target(
            "smap_bytes", bytes_cases(), _run_bytes("smap"), ci_examples=150, doc="load_surface_map, bytes"
        ),
        Target(
            "smap_h5", h5_cases("smap"), _run_h5("smap"), ci_examples=120, doc="load_surface_map, odd HDF5"
        ),
        Target("robot_dict", robot_dicts(), _spec_dict, ci_examples=120, doc="spec_from_dict + Robot + arms"),
        Target("robot_file", robot_files(), _spec_file, ci_examples=100, doc="Robot(TOML/YAML file) + arms"),
        Target("robot_urdf", urdf_cases(), _urdf, ci_examples=150, doc="Robot of a mutated URDF + arm"),
        Target("pose_text", pose_texts(), _parse_pose, ci_examples=200, doc="parse_pose6 / parse_base_pose"),
        Target(
            "polygon", polygon_inputs(), _parse_polygon, ci_examples=200, doc="parse_polygon(text or array)"
        ),
        Target(
            "prop_rpy",
            rpy_batches(),
            _prop_rpy,
            kind="property",
            ci_examples=150,
            doc="rpy -> matrix -> rpy -> matrix",
        ),
        Target(
            "prop_invert",
            rigid_transforms(),
            _prop_invert,
            kind="property",
            ci_examples=150,
            doc="invert_transforms(T) @ T = I",
        ),
        Target(
            "prop_basepose",
            BASE_POSES,
            _prop_basepose,
            kind="property",
            ci_examples=150,
            doc="BasePose matrix / from_matrix round trip",
        ),
    ]
}
