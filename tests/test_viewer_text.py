"""The viewer shows every string of a result as text: no HTML, no link reaches viser's markdown."""

from __future__ import annotations

import html
import json
import re
import shutil
from typing import Any

import numpy as np
import pytest
from markdown_it import MarkdownIt

from baseplace.viz.viewer import markdown_text, serve
from conftest import DATA

PAYLOADS = (
    '<iframe srcdoc="<script>alert(1)</script>">',
    "<img src=x onerror=alert(1)>",
    "[x](javascript:alert(1))",
)
HOSTILE = " ".join(PAYLOADS)
ROBOT_FILE = "<img src=x onerror=alert(1)>.toml"  # a file name may carry it too (no "/" in it)
# CommonMark with raw HTML passed through, as viser's renderer (react-markdown + raw HTML) does
RENDER = MarkdownIt("commonmark", {"html": True}).enable("table").enable("strikethrough")


def rendered(markdown: str) -> tuple[list[str], str]:
    """The tags the markdown renders to, and the text a reader sees."""
    out = RENDER.render(markdown)
    tags = re.findall(r"</?([a-zA-Z][\w-]*)", out)
    return tags, html.unescape(re.sub(r"<[^>]*>", "", out)).strip()


@pytest.mark.parametrize(
    "text",
    [
        *PAYLOADS,
        HOSTILE,
        "`code` *em* _u_ ~~s~~ # h | a | b | www.evil.com https://x.y/z <b>&amp;</b>",
        "a\nb\tc",
    ],
)
def test_markdown_text_renders_as_the_same_text_and_nothing_else(text):
    markdown = markdown_text(text)
    assert "<" not in markdown and "javascript:" not in markdown and "\n" not in markdown
    tags, seen = rendered(markdown)
    assert tags == ["p", "p"], tags
    assert seen == " ".join(text.split())


def poisoned(obj: Any, keep: set[str], key: str = "") -> Any:
    """``obj`` with every string the viewer does not need to load the scene replaced by the payloads."""
    if isinstance(obj, dict):
        return {k if k in keep else f"{k}{HOSTILE}": poisoned(v, keep, k) for k, v in obj.items()}
    if isinstance(obj, list):
        return [poisoned(v, keep, key) for v in obj]
    if isinstance(obj, str) and key not in keep:
        return HOSTILE
    return obj


def test_a_hostile_result_reaches_viser_as_text(tmp_path, monkeypatch):
    from viser._gui_api import GuiApi

    shutil.copy(DATA / "planar3.urdf", tmp_path / "planar3.urdf")
    shutil.copy(DATA / "planar3.toml", tmp_path / ROBOT_FILE)
    rng = np.random.default_rng(0)
    np.save(tmp_path / "floor.npy", np.c_[rng.uniform(-1, 1, (3000, 2)), rng.normal(0, 0.002, 3000)])
    result = {
        "kind": "place",
        "error": HOSTILE,
        "robot": {"name": HOSTILE, "file": ROBOT_FILE, "arm": "arm", "base_frame": HOSTILE},
        "inputs": {"cloud": "floor.npy", "robot": ROBOT_FILE, "strategy": HOSTILE, "object": HOSTILE},
        "failures": {HOSTILE: 3},
        "collisions": {"most_frequent": [{"link": HOSTILE, "touched": HOSTILE, "count": 1}]},
        "strategy": HOSTILE,
        "placements": [
            {
                "base_pose": np.eye(4).tolist(),
                "region": HOSTILE,
                "note": HOSTILE,
                "joints": [{"joint3": 0.1, "lift": 0.2, "joint1": 0.3, "joint2": 0.4}],
            }
        ],
    }
    keep = {"kind", "cloud", "file", "arm", "placements", "base_pose", "joints", "joint1", "joint2", "joint3",
            "lift", "inputs", "robot"}  # fmt: skip
    path = tmp_path / "result.json"
    path.write_text(json.dumps(poisoned(result, keep) | {"error": HOSTILE}))

    shown: list[str] = []
    add_markdown = GuiApi.add_markdown

    def capture(self: GuiApi, content: str, *args: Any, **kwargs: Any) -> Any:
        shown.append(content)
        return add_markdown(self, content, *args, **kwargs)

    monkeypatch.setattr(GuiApi, "add_markdown", capture)
    server = serve(path, port=0, block=False)
    server.stop()
    assert shown, "the viewer showed no markdown"
    for markdown in shown:
        assert "<" not in markdown and "javascript:" not in markdown, markdown
        tags, seen = rendered(markdown)
        assert set(tags) <= {"p", "strong"}, tags
        assert HOSTILE in seen and ROBOT_FILE in seen, seen  # shown, as the text it is
