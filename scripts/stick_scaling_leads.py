"""Where a stick-scaling ladder's slips start: the true-inertia stretch before each onset, and the
rise and fall of the large slips, per rung (README "Stick-phase inertia scaling", 16-seed ladder).

    .venv/bin/python scripts/stick_scaling_leads.py LADDER_DIR [--big 0.05]

LADDER_DIR is a `gouge accuracy CONFIG --stick-scaling ... --out LADDER_DIR` folder
(scaling_runs.json and lam_<L>/seed_<S>/run.h5). Per rung, over the slips after the transient
(the ladder's 20 %):

* true lead: onset time minus the start of the lambda = 1 stretch that holds the onset (series
  column stick_scaling; at lambda 1 the whole run, so not shown): how far before the onset the
  rollback put the run back at true inertia. The rules promise at least slips.lead before the
  onset *estimate of the scaled stretch*; this is the distance to the true onset.
* rise = peak_time - onset_time and fall = end_time - peak_time of the slips with a stress drop
  >= --big (the duration is their sum), from the run file's catalog.
* after the switch: the first 200 t0 of every true-inertia stretch that follows a scaled row
  (a rollback; at lambda 1, as control, the 200 t0 from 1.25 leads before each onset, where a
  rollback lands): the median of the largest wall speed [V_s], the share of stretches in which it
  reaches slips.end_factor V_s (the onset level), and the median time to the largest tau/sigma.
* late-stick creep: wall displacement / (V_s time) over the rows more than 10,000 t0 after the
  previous slip's end and more than two leads before the next onset (the spring loads the layer at
  k (V_s - creep)); mean [seed spread].
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import h5py
import yaml
import numpy as np

from gouge_cli.config import build_config
from gouge_cli.driver.slips import lead_time
from gouge_cli.io.runfile import RunReader, attr_value


def rung(folder: Path, runs: list[dict], lam: float, big: float, lead: float, V: float, end: float) -> dict:
    leads, rise, fall, creep, v_after, peak_after = [], [], [], [], [], []
    for r in runs:
        t_skip = r["t_load"] + 0.2 * r["duration"]
        path = folder / f"lam_{lam:g}" / f"seed_{r['seed']}"
        with RunReader(path) as run:
            s = run.series(("time", "wall_x", "wall_vx", "tau_over_sigma", "stick_scaling"))
        t, x, tau = s["time"], s["wall_x"], s["tau_over_sigma"]
        sc = s["stick_scaling"] if s["stick_scaling"] is not None else np.ones_like(t)
        true_start = np.zeros(t.size)              # start time of the lambda = 1 stretch holding each row
        for i in range(t.size):
            true_start[i] = t[i] if (i == 0 or sc[i - 1] > 1.0 or sc[i] > 1.0) else true_start[i - 1]
        with h5py.File(path / "run.h5", "r") as f:
            cat = [dict(f["slips"][k].attrs) for k in sorted(f["slips"])]
        on = np.array([c["onset_time"] for c in cat])
        ends = np.array([c["end_time"] for c in cat])
        starts = (np.flatnonzero((sc[1:] <= 1.0) & (sc[:-1] > 1.0)) + 1 if lam > 1.0
                  else np.searchsorted(t, on[on - 1.25 * lead > t_skip] - 1.25 * lead))
        for i in starts[t[starts] >= t_skip]:
            m = (t >= t[i]) & (t <= t[i] + 200.0)
            v_after.append(np.max(s["wall_vx"][m]) / V)
            peak_after.append(t[m][np.argmax(tau[m])] - t[i])
        for c in cat:
            if c["onset_time"] < t_skip:
                continue
            i = min(np.searchsorted(t, c["onset_time"]), t.size - 1)
            if lam > 1.0:
                leads.append(c["onset_time"] - true_start[i])
            if c["stress_drop"] >= big:
                rise.append(c["peak_time"] - c["onset_time"])
                fall.append(c["end_time"] - c["peak_time"])
        tm, dx, dt = 0.5 * (t[1:] + t[:-1]), np.diff(x), np.diff(t)
        k = np.searchsorted(on, tm)
        since = tm - np.where(k > 0, ends[np.maximum(k - 1, 0)], -np.inf)
        until = np.where(k < on.size, on[np.minimum(k, on.size - 1)], np.inf) - tm
        m = (tm >= t_skip) & (since > 1e4) & (until > 2 * lead) & np.isfinite(until)
        creep.append(dx[m].sum() / dt[m].sum() / V)
    leads = np.array(leads)
    return {"lambda": lam, "seeds": len(runs), "slips": len(leads) if lam > 1 else None,
            "true_lead_median": float(np.median(leads)) if leads.size else float("nan"),
            "below_lead": float(np.mean(leads < lead)) if leads.size else float("nan"),
            "below_quarter_lead": float(np.mean(leads < lead / 4)) if leads.size else float("nan"),
            "big_slips": len(rise), "rise": float(np.mean(rise)), "fall": float(np.mean(fall)),
            "creep": float(np.mean(creep)), "creep_spread": float(np.std(creep, ddof=1)),
            "switches": len(v_after), "v_after": float(np.median(v_after)),
            "onset_level_after": float(np.mean(np.array(v_after) >= end)), "tau_peak_after": float(np.median(peak_after))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--big", type=float, default=0.05)
    a = ap.parse_args()
    runs = json.loads((a.folder / "scaling_runs.json").read_text())
    with RunReader(a.folder / "lam_1" / f"seed_{runs[0]['seed']}") as run:
        config = build_config(yaml.safe_load(attr_value(run.h5.attrs, "config")))
    lead, V, end = lead_time(config), config.loading.velocity, config.slips.end_factor
    print(f"slips.lead {lead:.0f} t0; large slips: stress drop >= {a.big}")
    for lam in sorted({r["lam"] for r in runs}):
        row = rung(a.folder, [r for r in runs if r["lam"] == lam], lam, a.big, lead, V, end)
        lead_s = "" if lam == 1.0 else (f"true lead median {row['true_lead_median']:.0f} t0, < lead {row['below_lead']:.0%}, "
                                         f"< lead/4 {row['below_quarter_lead']:.0%}; ")
        print(f"lambda {lam:g} ({row['seeds']} seeds): {lead_s}large slips {row['big_slips']}: rise {row['rise']:.0f} "
              f"fall {row['fall']:.0f} t0; late-stick creep {row['creep']:.3f} [{row['creep_spread']:.3f}] V_s; "
              f"{'after a rollback' if lam > 1 else 'control'} ({row['switches']}): max v {row['v_after']:.1f} V_s, "
              f">= {end:g} V_s {row['onset_level_after']:.0%}, tau peak after {row['tau_peak_after']:.0f} t0")


if __name__ == "__main__":
    main()
