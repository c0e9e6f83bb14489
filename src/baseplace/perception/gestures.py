"""The operator's gesture from 21 hand landmarks: Scan, Point, Stop or none (seed 004, section 3.1).

The seed trains a small MLP (Kazuhito00's hand-gesture-recognition-using-mediapipe) on landmark
coordinates but publishes neither its training data nor what its three gestures look like. This
module uses a rule instead, on purpose:

* the three gestures differ only in which fingers are stretched, and whether a finger is stretched
  is a geometric fact of its landmarks: its tip lies farther from the wrist than its PIP joint
  (a curled finger folds its tip back towards the palm) and its segments run in one direction;
* the rule is invariant to the hand's size, position and rotation in the image, needs no data,
  and every decision it makes can be explained per finger (the report lists them);
* an MLP trained on landmarks we generate ourselves would only learn this rule back.

The shapes (the seed leaves them open): **Point** the index finger stretched, middle, ring and
little finger curled (the thumb is free); **Scan** index and middle stretched, ring and little
curled (a "V"); **Stop** all four fingers stretched (an open palm); anything else is **none**.
A finger neither clearly stretched nor clearly curled makes the gesture none, never a guess.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError

WRIST = 0
FINGERS = {
    "index": (5, 6, 7, 8),
    "middle": (9, 10, 11, 12),
    "ring": (13, 14, 15, 16),
    "little": (17, 18, 19, 20),
}
"""MediaPipe landmark indices of each finger: MCP, PIP, DIP, TIP."""
GESTURES = ("Scan", "Point", "Stop", "none")
SHAPES = {
    "Point": (True, False, False, False),
    "Scan": (True, True, False, False),
    "Stop": (True, True, True, True),
}
"""Gesture -> stretched (index, middle, ring, little)."""

STRETCHED_RATIO = 1.15
"""A finger is stretched when |tip - wrist| exceeds |PIP - wrist| by this factor (a straight finger's
ratio is about 1.4-1.6, a half-bent one's about 1.1) ..."""
STRETCHED_COS = 0.4
"""... and PIP->TIP bends less than acos(0.4) = 66 deg against MCP->PIP. Chosen on the pointing
experiment's development scenes (docs/protocols/pointing.md): with 1.5 px landmark noise on hands
80 px long, a straight index finger measured down to 0.51 there (the segments are 5-15 px); the
first rule, 0.7 on each of PIP->DIP and DIP->TIP, called 11 of 100 pointing hands unclear."""
CURLED_RATIO = 1.0
"""A finger is curled when its tip lies no farther from the wrist than its PIP joint."""


@dataclass(frozen=True)
class Gesture:
    """A classified hand.

    Attributes:
        name: Scan, Point, Stop or none.
        fingers: finger -> "stretched", "curled" or "unclear".
    """

    name: str
    fingers: dict[str, str]

    def to_json(self) -> dict[str, Any]:
        """``{"name", "fingers"}``."""
        return {"name": self.name, "fingers": dict(self.fingers)}


def finger_state(landmarks: ArrayLike, finger: str) -> str:
    """Whether one finger is "stretched", "curled" or "unclear".

    Args:
        landmarks: (21, 2) or (21, 3) landmarks in one unit on every axis (pixels, or metres).
        finger: index, middle, ring or little.
    """
    L = np.asarray(landmarks, dtype=float)
    mcp, pip, _, tip = (L[i] for i in FINGERS[finger])
    wrist = L[WRIST]
    d_tip, d_pip = float(np.linalg.norm(tip - wrist)), float(np.linalg.norm(pip - wrist))
    if d_pip <= 0:
        return "unclear"
    ratio = d_tip / d_pip
    if ratio <= CURLED_RATIO:
        return "curled"
    base, rest = pip - mcp, tip - pip
    denom = float(np.linalg.norm(base) * np.linalg.norm(rest))
    straightness = float(base @ rest) / denom if denom > 0 else -1.0
    if ratio >= STRETCHED_RATIO and straightness >= STRETCHED_COS:
        return "stretched"
    return "unclear"


def classify(landmarks: ArrayLike) -> Gesture:
    """The gesture of one hand.

    Args:
        landmarks: (21, 2) or (21, 3) MediaPipe landmarks with one unit on every axis: pixels
            (normalised x times the image width, y times its height, z times the width, as
            MediaPipe scales z) or metres.

    Raises:
        InputError: not 21 finite landmarks.
    """
    L = np.asarray(landmarks, dtype=float)
    if L.ndim != 2 or L.shape[0] != 21 or L.shape[1] not in (2, 3) or not np.all(np.isfinite(L)):
        raise InputError(f"a hand needs 21 finite landmarks of 2 or 3 coordinates, got shape {L.shape}")
    fingers = {f: finger_state(L, f) for f in FINGERS}
    if "unclear" not in fingers.values():
        stretched = tuple(fingers[f] == "stretched" for f in FINGERS)
        for name, shape in SHAPES.items():
            if stretched == shape:
                return Gesture(name, fingers)
    return Gesture("none", fingers)


__all__ = ["FINGERS", "GESTURES", "Gesture", "classify", "finger_state"]
