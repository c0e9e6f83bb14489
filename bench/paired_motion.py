"""The reaching-motion check of this checkout against another checkout's, paired in one process (development only).

Between processes this shared machine drifts by as much as a change gains (see
``paired_kernel.py``), so both run here, on the same collision models and inputs. The other
checkout's ``baseplace/placement/motion.py`` and ``baseplace/robots/ik.py`` (``--other``: that
checkout's root, e.g. a ``git worktree`` of the commit to compare with) are loaded as modules of
their own, its motion module wired to its IK; everything else (the environment, the state
filter and its kernel, coal, OMPL) is this checkout's, so a change there is not measured here
(``paired_kernel.py`` pairs the state kernel).

Inputs: the checks of a ``bench_motion_verdicts.py`` results file (development seeds only, as
``profile_motion_stages.py`` replays them), each checkout's ``MotionSettings()`` and the file's
OMPL seed per check. Per check the two take turns ``--turns`` times each (the first turn of each
not counted: caches), and the fastest of the rest is kept. Reported: the medians and means, the
per-check ratio's median and quartiles, how many motions each found in its last turn and how many
checks gave the same answer (no motion in both, or the same path and approach to 1e-9 rad).

Usage: python bench/paired_motion.py --other ../base [--results motion_verdicts_s17_final_a] [--turns 3] [--name paired_motion]
"""

from __future__ import annotations

from baseplace.placement.motion import MotionChecker, MotionSettings
from common import other_module, report
from profile_motion_stages import paired_arguments, paired_checks


def main() -> None:
    args, rows = paired_arguments(__doc__ or "", 3, "paired_motion")
    other_ik = other_module(args.other, "robots/ik.py", "other_ik")
    other_motion = other_module(args.other, "placement/motion.py", "other_motion")
    other_motion.DampedLeastSquaresIK = other_ik.DampedLeastSquaresIK  # type: ignore[attr-defined]
    checkers = {
        "this": (MotionChecker, MotionSettings),
        "other": (other_motion.MotionChecker, other_motion.MotionSettings),  # type: ignore[attr-defined]
    }
    report(args.name, paired_checks(args, rows, checkers.__getitem__))


if __name__ == "__main__":
    main()
