"""The live progress line fits the terminal: at 80 columns every number is whole (issue 60)."""

from __future__ import annotations

import io
import re
import time

import pytest
from rich.console import Console

from gouge_cli.driver.progress import ProgressReport


def _last_line(width: int, label: str, info: str) -> str:
    buf = io.StringIO()
    console = Console(file=buf, width=width, force_terminal=True, color_system=None)
    report = ProgressReport(label, 2.5e6, 2000, console=console, live=True)
    report.update(0.0, 0)
    time.sleep(0.2)
    report.update(123456.7, 5000, info)
    time.sleep(0.2)
    report.update(234567.8, 9000, info)
    report.close()
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", buf.getvalue()).replace("\r", "\n")
    return [line for line in text.splitlines() if line.strip()][-1]


@pytest.mark.parametrize("width", [80, 100, 160])
@pytest.mark.parametrize("label", ["loading", "slip 12 perm_3e-06"])
def test_the_progress_line_keeps_its_numbers_whole(width, label):
    line = _last_line(width, label, "tau/sigma 0.123, slips 3")
    assert len(line) <= width
    assert label in line
    assert re.search(r"(2\.35e\+05/|t = 2\.346e\+05 / )2\.5e\+06 t0", line), line   # simulated time, whole
    assert re.search(r"\d+\.\d+ M(gs/s| grain-steps/s)", line), line          # the rate, whole
    assert re.search(r"ETA \d+:\d\d:\d\d", line), line                        # the ETA, whole
    if width >= 160:
        assert "tau/sigma 0.123, slips 3" in line and "…" not in line
