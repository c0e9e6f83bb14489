"""The one verification every placement method uses before it returns a pose (seed 000 Alg. 2).

A candidate base pose is accepted only if (1) its footprint lies inside the polygon of its
planar region (when it has one), (2) IK reaches every target from it, (3) the whole robot at
each IK configuration is free of self-collision and of the obstacle voxels, and, when a
:class:`~baseplace.placement.motion.MotionChecker` is given, (4) the arm can move there from its
stowed configuration without collision (rejection reason ``motion``).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from shapely.geometry import MultiPolygon, Polygon

from baseplace.geometry.poses import FloatArray, invert_transforms
from baseplace.placement.motion import MOTION_FAILURES, MotionChecker
from baseplace.placement.verified import Candidate, Placement
from baseplace.robots.ik import IKSolver
from baseplace.robots.model import Arm
from baseplace.terrain.polygons import footprint_inside
from baseplace.world.environment import Environment

Failure = Literal["footprint", "no_ik", "collision", "motion", "exhausted"]


@dataclass
class Verifier:
    """Checks candidates; counts why the rejected ones failed.

    Attributes:
        arm: the arm that must reach the targets.
        ik: the IK solver.
        environment: obstacle collision checker.
        targets: (K, 4, 4) world targets.
        polygons: region id -> polygon, for the footprint test.
        outline: (F, 2) footprint in the base frame.
        failures: counts per failure reason.
        contacts: per (robot link, what it touched), the candidates rejected for that contact
            (what: an obstacle group such as "support" or "obstacle", "grasped_object" for a link
            other than the hand, or "self: <link>").
        rejected: per rejected candidate, (x, y) [m], the reason and its first contact (or None).
        motion: the reaching-motion check, or None to skip it.
        motion_failures: per reason the motion check gave (:data:`~baseplace.placement.motion.MOTION_FAILURES`),
            the candidates rejected for it.
    """

    arm: Arm
    ik: IKSolver
    environment: Environment
    targets: FloatArray
    polygons: dict[int, Polygon | MultiPolygon]
    outline: FloatArray
    failures: Counter[str] = field(default_factory=Counter)
    contacts: Counter[tuple[str, str]] = field(default_factory=Counter)
    rejected: list[tuple[tuple[float, float], str, tuple[str, str] | None]] = field(default_factory=list)
    motion: MotionChecker | None = None
    motion_failures: Counter[str] = field(default_factory=Counter)

    def check(self, candidate: Candidate, rng: np.random.Generator) -> Placement | None:
        """The verified placement, or None (the reason is counted in ``failures``)."""
        T = candidate.T_world_base
        if not self.footprint_fits(candidate):
            self._reject(T, "footprint")
            return None
        T_base_world = invert_transforms(T)
        joints = []
        for target in self.targets:
            q = self.ik.solve(T_base_world @ target, rng)
            if q is None:
                self._reject(T, "no_ik")
                return None
            joints.append(q)
        for q in joints:
            contacts = self.collisions(q, T)
            if contacts is not None:
                self.contacts.update(contacts)
                self._reject(T, "collision", contacts[0] if contacts else None)
                return None
        motions = None
        if self.motion is not None:
            motions = []
            for k, target in enumerate(self.targets):
                motion = self.motion.check(joints[k], T, target, seed=int(rng.integers(2**31 - 1)))
                if motion is None:
                    blocked = self.motion.last_contacts
                    self.contacts.update(blocked)
                    assert self.motion.last_failure is not None  # check sets it whenever it finds no motion
                    self.motion_failures[self.motion.last_failure] += 1
                    self._reject(T, "motion", blocked[0] if blocked else None)
                    return None
                motions.append(motion)
                joints[k] = motion.approach[-1]  # the motion may end in another checked grasp configuration
        return Placement(T.copy(), candidate.region, candidate.reachability, joints, self.arm.joint_names,
                         motions, targets=self.targets)  # fmt: skip

    def footprint_fits(self, candidate: Candidate) -> bool:
        """Check (1): the footprint lies inside its region's polygon (always True off the regions)."""
        if candidate.region < 0:
            return True
        return bool(footprint_inside(self.polygons[candidate.region], self.outline, candidate.T_world_base))

    def collisions(self, q: FloatArray, T_world_base: FloatArray) -> list[tuple[str, str]] | None:
        """Check (3) of arm joints (n,) at a base pose (4, 4): None when free, else every contact.

        A contact is (robot link, what it touched), as :attr:`contacts` counts them. One call gives
        the verdict and the reason: :meth:`Environment.contacts_arm` asks coal about every pair the
        state filter's spheres leave (what :meth:`Environment.colliding_arm` asks, up to its first
        touching pair), so it is empty exactly when that is False; a rejected candidate no longer
        runs coal twice (tests/test_verify_contacts.py: the same verdicts and contacts as coal on
        every pair).
        """
        contacts = self.environment.contacts_arm(self.arm, q, T_world_base)
        return contacts or None

    def _reject(self, T: FloatArray, reason: str, contact: tuple[str, str] | None = None) -> None:
        self.failures[reason] += 1
        self.rejected.append(((float(T[0, 3]), float(T[1, 3])), reason, contact))


def contact_summary(contacts: Counter[tuple[str, str]]) -> list[dict[str, object]]:
    """Contacts most frequent first, for JSON: [{"link": ..., "touched": ..., "candidates": n}]."""
    return [{"link": link, "touched": what, "candidates": n} for (link, what), n in contacts.most_common()]


def motion_failure_summary(counts: Counter[str]) -> str:
    """One phrase for an error line: why the reaching motion was not found, the two most frequent reasons."""
    if not counts:
        return ""
    reasons = [f"{MOTION_FAILURES.get(code, code)} ({_candidates(n)})" for code, n in counts.most_common(2)]
    return "no reaching motion: " + ", ".join(reasons)


def most_frequent_contact(contacts: Counter[tuple[str, str]]) -> str:
    """One phrase for an error line: the (link, touched) pair in the most rejected candidates."""
    if not contacts:
        return ""
    (link, what), n = contacts.most_common(1)[0]
    return f"most often link {link} touched {what} ({_candidates(n)})"


def _candidates(n: int) -> str:
    return f"{n} candidate" if n == 1 else f"{n} candidates"
