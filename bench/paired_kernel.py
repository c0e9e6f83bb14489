"""The reaching-motion check with this checkout's state kernel against another checkout's, paired in one process (development only).

Between processes this shared machine drifts by as much as a kernel change gains (session 33:
alternated runs of ``profile_motion_stages.py`` read x 0.79 where the paired figure is x 0.93),
so both kernels run here, on the same collision models and inputs. The other checkout's
``baseplace/world/state_kernel.py`` (``--other``: that checkout's root, e.g. a ``git worktree``
of the commit to compare with) is loaded as a module of its own and swapped into
:mod:`baseplace.world.state_filter` for its turns; everything else (the state filter's Python
side, the planner, coal) is this checkout's, so the kernels must share their arguments.

Inputs: the checks of a ``bench_motion_verdicts.py`` results file (development seeds only, as
``profile_motion_stages.py`` replays them), ``MotionSettings()`` and the file's OMPL seed per
check. Per check the two kernels take turns ``--turns`` times each (the first turn of each not
counted: caches), and the fastest of the rest is kept. Reported: the medians and means, the
per-check ratio's median and quartiles, how many motions each found in its last turn and how many
checks gave the same answer (the verdicts are coal's, so they should agree)
(:func:`profile_motion_stages.paired_checks`).

Usage: python bench/paired_kernel.py --other ../base [--results motion_verdicts_s17_final_a] [--turns 4] [--name paired_kernel]
"""

from __future__ import annotations

from typing import Any

import baseplace.world.state_filter as state_filter
import baseplace.world.state_kernel as this_kernel
from baseplace.placement.motion import MotionChecker, MotionSettings
from common import other_module, report
from profile_motion_stages import paired_arguments, paired_checks

SWAPPED = ("_uncertified_line", "_uncertified_states", "_touch_proven")
"""The kernel entry points the state filter calls. A kernel without ``_touch_proven`` (before
session 35) proved no contact: coal decided every state the spheres left (:func:`_no_proof`)."""


def _no_proof(*args: Any) -> bool:
    """A state kernel's contact proof where it had none: nothing proven, coal decides."""
    return False


def main() -> None:
    args, rows = paired_arguments(__doc__ or "", 4, "paired_kernel")
    kernels = {
        "this": this_kernel,
        "other": other_module(args.other, "world/state_kernel.py", "other_state_kernel"),
    }

    def side(name: str) -> tuple[Any, Any]:
        for entry in SWAPPED:
            setattr(state_filter, entry, getattr(kernels[name], entry, _no_proof))
        return MotionChecker, MotionSettings

    report(args.name, paired_checks(args, rows, side))


if __name__ == "__main__":
    main()
