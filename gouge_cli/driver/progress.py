"""Progress report: a rich bar with simulated time, ETA and grain-steps/s on a terminal,
plain lines (every ``every_s`` seconds) when the output is not a terminal (batch scripts).
:class:`SettleReport` is compaction's: progress and ETA toward the settling criterion."""

from __future__ import annotations

import math
import sys
import time

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from .settling import SettleCheck, SettleTracker


class ProgressReport:
    def __init__(self, label: str, total_time: float, n_grains: int, console: Console | None = None,
                 live: bool | None = None, every_s: float = 10.0):
        self.console = console or Console(stderr=True)
        self.live = sys.stderr.isatty() if live is None else live
        self.label, self.total, self.n = label, total_time, n_grains
        self.every_s = every_s
        self._t0 = time.perf_counter()
        self._last_print = self._t0
        self._first = None               # (wall time, simulated time, step) at the first update
        self._progress = None
        # below ~120 columns the bar and the labels shrink, so that an 80-column terminal shows
        # every field whole (rich cuts an overlong line with an ellipsis)
        self._narrow = self.console.width < 120
        if self.live:
            if self._narrow:      # no elapsed time; the info (tau/sigma, slips) is what gets cut
                columns = (TextColumn("[bold]{task.description}"), BarColumn(bar_width=8),
                           TextColumn("{task.completed:.3g}/{task.total:.3g} t0"), TextColumn("{task.fields[rate]}"),
                           TextColumn("{task.fields[info]}"), TextColumn("ETA"), TimeRemainingColumn())
            else:
                columns = (TextColumn("[bold]{task.description}"), BarColumn(),
                           TextColumn("t = {task.completed:.4g} / {task.total:.4g} t0"),
                           TextColumn("{task.fields[rate]}"), TextColumn("{task.fields[info]}"),
                           TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())
            self._progress = Progress(*columns, console=self.console, transient=False)
            self._progress.start()
            self._task = self._progress.add_task(label, total=total_time, rate="", info="")

    def update(self, elapsed_sim: float, step: int, info: str = ""):
        """Rate and ETA count from the first update on: the interval before it holds the one-off
        numba compile (tens of seconds on a fresh machine), which made the first ETAs hours long."""
        now = time.perf_counter()
        if self._first is None:
            self._first = (now, elapsed_sim, step)
        t1, _, step1 = self._first
        rate = (step - step1) * self.n / (now - t1) if now > t1 else 0.0
        rate_text = f"{rate / 1e6:.2f} M grain-steps/s"
        if self._progress is not None:
            if self._narrow:
                rate_text = f"{rate / 1e6:.1f} Mgs/s"
                fixed = (f"{self.label} {'x' * 8} {min(elapsed_sim, self.total):.3g}/{self.total:.3g} t0 "
                         f"{rate_text}  ETA 00:00:00")
                room = self.console.width - len(fixed) - 2
                if len(info) > room:
                    info = info[:max(room - 1, 0)] + "…" if room > 1 else ""
            self._progress.update(self._task, completed=min(elapsed_sim, self.total), rate=rate_text, info=info)
        elif now - self._last_print >= self.every_s:
            self._last_print = now
            frac = elapsed_sim / self.total if self.total else 1.0
            eta = format_eta(self.eta_seconds(now, elapsed_sim))
            print(f"{self.label}: t = {elapsed_sim:.6g} / {self.total:.6g} t0 ({100 * frac:.1f}%), "
                  f"{rate_text}, ETA {eta} {info}", file=sys.stderr, flush=True)

    def eta_seconds(self, now: float, elapsed_sim: float) -> float:
        """Wall seconds to the end at the speed since the first update; inf before it is known."""
        t1, sim1, _ = self._first
        if elapsed_sim >= self.total:
            return 0.0
        if not (now > t1 and elapsed_sim > sim1):
            return math.inf
        return (self.total - elapsed_sim) * (now - t1) / (elapsed_sim - sim1)

    def close(self):
        if self._progress is not None:
            self._progress.stop()


def format_eta(seconds: float, capped: bool = False) -> str:
    """'?' while unknown, '<= ...' when it is the time left to compaction.max_time."""
    if not math.isfinite(seconds):
        return "?"
    m, sec = divmod(int(round(seconds)), 60)
    text = f"{m // 60}:{m % 60:02d}:{sec:02d}"
    return f"<= {text}" if capped else text


class SettleReport:
    """Compaction's progress toward settling (settling.SettleTracker): fraction, the conditions
    still unmet, grain-steps/s and the ETA extrapolated from the recent decay of the speeds."""

    def __init__(self, max_time: float, n_grains: int, console: Console | None = None,
                 live: bool | None = None, every_s: float = 10.0):
        self.console = console or Console(stderr=True)
        self.live = sys.stderr.isatty() if live is None else live
        self.n, self.every_s = n_grains, every_s
        self.tracker = SettleTracker(max_time)
        self._t0 = time.perf_counter()
        self._last_print = self._t0
        self._step0 = None
        self.last: dict | None = None
        self._progress = None
        if self.live:
            self._progress = Progress(
                TextColumn("[bold]compaction"), BarColumn(), TextColumn("{task.percentage:>3.0f}% settled"),
                TextColumn("{task.fields[info]}"), TextColumn("{task.fields[rate]}"), TimeElapsedColumn(),
                TextColumn("ETA {task.fields[eta]}"), console=self.console, transient=False)
            self._progress.start()
            self._task = self._progress.add_task("compaction", total=1.0, rate="", info="", eta="?")

    def update(self, check: SettleCheck, step: int):
        now = time.perf_counter()
        if self._step0 is None:
            self._step0 = step
        wall = max(now - self._t0, 1e-9)
        self.last = out = self.tracker.update(check, wall)
        rate = f"{(step - self._step0) * self.n / wall / 1e6:.2f} M grain-steps/s"
        info = f"t = {check.elapsed:.4g} t0, " + ("waiting for " + ", ".join(out["unmet"]) if out["unmet"] else "criterion met")
        eta = format_eta(out["eta"], out["capped"])
        if self._progress is not None:
            self._progress.update(self._task, completed=out["fraction"], rate=rate, info=info, eta=eta)
        elif now - self._last_print >= self.every_s or not out["unmet"]:
            self._last_print = now
            print(f"compaction: {100 * out['fraction']:.0f}% settled, {info}, {rate}, ETA {eta}",
                  file=sys.stderr, flush=True)

    def close(self):
        if self._progress is not None:
            self._progress.stop()


class ItemProgress:
    """Progress of a loop over ``total`` items (movie frames, exported snapshots): one plain line on
    stderr every ``every_s`` seconds, on a terminal or not, with the count and an ETA from the mean
    pace so far; ``quiet`` prints nothing."""

    def __init__(self, label: str, total: int, every_s: float = 10.0, quiet: bool = False):
        self.label, self.total, self.every_s, self.quiet = label, int(total), every_s, quiet
        self._t0 = self._last = time.perf_counter()

    def update(self, done: int):
        now = time.perf_counter()
        if self.quiet or now - self._last < self.every_s or done >= self.total:
            return
        self._last = now
        eta = (now - self._t0) * (self.total - done) / done if done else math.inf
        print(f"{self.label}: {done} / {self.total} ({100 * done / max(self.total, 1):.0f}%), ETA {format_eta(eta)}",
              file=sys.stderr, flush=True)
