"""Progress report: a rich bar with simulated time, ETA and grain-steps/s on a terminal,
plain lines (every ``every_s`` seconds) when the output is not a terminal (batch scripts)."""

from __future__ import annotations

import sys
import time

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn


class ProgressReport:
    def __init__(self, label: str, total_time: float, n_grains: int, console: Console | None = None,
                 live: bool | None = None, every_s: float = 10.0):
        self.console = console or Console(stderr=True)
        self.live = sys.stderr.isatty() if live is None else live
        self.label, self.total, self.n = label, total_time, n_grains
        self.every_s = every_s
        self._t0 = time.perf_counter()
        self._last_print = self._t0
        self._step0 = None
        self._progress = None
        if self.live:
            self._progress = Progress(
                TextColumn("[bold]{task.description}"), BarColumn(),
                TextColumn("t = {task.completed:.4g} / {task.total:.4g} t0"),
                TextColumn("{task.fields[rate]}"), TextColumn("{task.fields[info]}"),
                TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                console=self.console, transient=False)
            self._progress.start()
            self._task = self._progress.add_task(label, total=total_time, rate="", info="")

    def update(self, elapsed_sim: float, step: int, info: str = ""):
        now = time.perf_counter()
        if self._step0 is None:
            self._step0 = step
        wall = max(now - self._t0, 1e-9)
        rate = (step - self._step0) * self.n / wall
        rate_text = f"{rate / 1e6:.2f} M grain-steps/s"
        if self._progress is not None:
            self._progress.update(self._task, completed=min(elapsed_sim, self.total), rate=rate_text, info=info)
        elif now - self._last_print >= self.every_s:
            self._last_print = now
            frac = elapsed_sim / self.total if self.total else 1.0
            eta = wall * (1.0 - frac) / frac if frac > 0 else float("nan")
            print(f"{self.label}: t = {elapsed_sim:.6g} / {self.total:.6g} t0 ({100 * frac:.1f}%), "
                  f"{rate_text}, ETA {eta:.0f} s {info}", file=sys.stderr, flush=True)

    def close(self):
        if self._progress is not None:
            self._progress.stop()
