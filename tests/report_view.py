"""A report page as headless Chromium lays it out at 1280 px: its DOM after load, and what
a reader's first screen holds (for tests/test_report.py and tests/test_reproduce.py)."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
WINDOW = (1280, 800)
"""The reader's window: a laptop's browser at 1280 px. The first screen is the viewport the
browser gives the page inside it (its height measured, not assumed)."""

# Measured in the page, after load, by the browser's own layout: where the headline table
# and the findings end, how many words each finding has, and at what scale each image is
# drawn (below 1, the browser shrank it and its text with it). Written to an attribute so
# that --dump-dom carries it out.
_MEASURE = """<script>
window.addEventListener('load', function () {
  function box(sel) {
    var e = document.querySelector(sel);
    if (!e) { return null; }
    var r = e.getBoundingClientRect();
    return {top: r.top, bottom: r.bottom, right: r.right};
  }
  var items = document.querySelectorAll('#findings-list li');
  document.body.setAttribute('data-glance', JSON.stringify({
    width: window.innerWidth, height: window.innerHeight,
    headline: box('#headline-table'), findings: box('#findings-list'),
    words: Array.prototype.map.call(items, function (li) {
      return li.textContent.trim().split(/\\s+/).length;
    }),
    scales: Array.prototype.map.call(document.images, function (i) {
      return i.naturalWidth ? i.getBoundingClientRect().width / i.naturalWidth : 0;
    })
  }));
});
</script>"""


def render(page: Path, workdir: Path, measure: bool = False) -> str:
    """The DOM of ``page`` after load in headless Chromium with a 1280x800 window; with
    ``measure``, a copy of the page that records :func:`first_screen`'s figures is loaded."""
    assert CHROMIUM, "headless Chromium is needed (Debian package chromium; make test installs it)"
    workdir.mkdir(parents=True, exist_ok=True)
    if measure:
        copy = workdir / "measured.html"
        copy.write_text(page.read_text().replace("</body>", _MEASURE + "\n</body>"))
        page = copy
    return subprocess.run(
        [
            CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
            "--no-first-run", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--hide-scrollbars", f"--user-data-dir={workdir / 'profile'}",
            f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=10000",
            "--dump-dom", page.as_uri(),
        ],
        capture_output=True, text=True, timeout=120,
    ).stdout  # fmt: skip


def first_screen(dom: str) -> dict[str, Any]:
    """What the measuring script recorded (:func:`render` with ``measure``)."""
    match = re.search(r'data-glance="([^"]*)"', dom)
    assert match, "the measuring script did not run"
    return json.loads(html.unescape(match.group(1)))


def check_first_screen(dom: str, max_words: int = 30) -> dict[str, Any]:
    """Assert that the first screen at 1280 px holds the headline table and the findings,
    that no finding runs past ``max_words`` words and that no image is shrunk; returns the
    measurements."""
    seen = first_screen(dom)
    assert seen["width"] == WINDOW[0], seen
    for part in ("headline", "findings"):
        box = seen[part]
        assert box is not None, f"the page has no {part}"
        assert box["top"] >= 0 and box["bottom"] <= seen["height"], (part, box, seen["height"])
        assert box["right"] <= seen["width"], (part, box)
    assert 1 <= len(seen["words"]) <= 3 and max(seen["words"]) <= max_words, seen["words"]
    # Drawn at (nearly) their own size: a figure's text is as large as it was drawn.
    assert seen["scales"] and min(seen["scales"]) >= 0.95, seen["scales"]
    return seen


__all__ = ["CHROMIUM", "WINDOW", "check_first_screen", "first_screen", "render"]
