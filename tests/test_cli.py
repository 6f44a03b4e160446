"""The command line, run as a real subprocess the way a user runs it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio

PIRL = [sys.executable, "-m", "pirl"]


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*PIRL, *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_render_writes_a_gif(tmp_path):
    out = tmp_path / "ep.gif"
    proc = _run(
        "render", "--policy", "boustrophedon", "--size", "20", "15", "3", "--seed", "1",
        "--out", str(out), cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "VCR" in proc.stdout
    frames = [f for f in imageio.get_reader(out)]
    assert len(frames) > 10
    assert frames[0].shape[:2] == (15 * 24, 20 * 24)


def test_bad_input_is_one_clear_line(tmp_path):
    proc = _run("render", "--size", "2", "30", "3", cwd=tmp_path)
    assert proc.returncode == 2
    assert "size=(2, 30, 3) is impossible" in proc.stderr
    assert "Traceback" not in proc.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("sise: [15, 15, 3]\n")
    proc = _run("render", "--config", str(bad), cwd=tmp_path)
    assert proc.returncode == 2
    assert "unknown setting 'sise'" in proc.stderr and "did you mean 'size'" in proc.stderr
    assert not (tmp_path / "episode.gif").exists()
