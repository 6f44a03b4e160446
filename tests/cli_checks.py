"""What every test of a user's mistake checks of a ``pirl`` subprocess, and the loopback
upload of a mission to an autopilot (MAVSDK) that several tests make."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path


def one_error_line(proc: subprocess.CompletedProcess, *needles: str) -> str:
    """Exit code 2, no traceback, exactly one line on stderr holding every needle."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def free_udp_port() -> int:
    """A UDP port on loopback that nothing holds now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def upload_with_mavsdk(plan: Path) -> tuple[list[dict], dict]:
    """Import ``plan`` with MAVSDK and upload it over loopback to a second MAVSDK instance
    acting as an autopilot (``tests/mavsdk_upload.py``, a process of its own): the plan's
    items and what the autopilot received (``imported``, ``items``)."""
    helper = Path(__file__).parent / "mavsdk_upload.py"
    proc = subprocess.run(
        [sys.executable, str(helper), str(plan), str(free_udp_port())],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    line = next((x for x in proc.stdout.splitlines() if x.startswith("RECEIVED ")), None)
    assert line is not None, proc.stdout + proc.stderr
    got = json.loads(line.removeprefix("RECEIVED "))
    items = json.loads(plan.read_text())["mission"]["items"]
    assert got["imported"] == len(items) == len(got["items"])
    return items, got
