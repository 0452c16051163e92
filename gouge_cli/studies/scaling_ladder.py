"""Stick-scaling ladder of `gouge accuracy --stick-scaling`: slip statistics and cost against lambda.

For each seed the scene is compacted once (compaction is never scaled); from that packing every
lambda of the ladder runs the same loading interval (config run.duration) with the slip recorder,
the stick-scaling controller (gouge_cli.driver.stick_scaling) and its rollbacks, on one thread. The guard
bound numerics.stick_inertial_max is lifted to 0.1 so that each rung measures lambda itself (the
largest inertial number reached is reported per rung).

Per rung: grain-steps and wall time per loading cycle (cycle = mean recurrence time at lambda = 1
over all seeds), and for each slip quantity Q in QUANTITIES, over the slips with onset after the
transient (the first `transient` fraction of the loading interval), pooled over seeds:

    diff = mean_lambda(Q) - mean_1(Q),  ci95 = 1.96 sqrt(var_lambda/n_lambda + var_1/n_1)  (Welch, normal)
    spread = standard deviation over seeds of the per-seed means at lambda = 1 (ddof 1)

A rung passes when |diff| <= spread for every Q; the recommended default is the largest lambda
such that it and every smaller rung pass.

With ``keep`` (``gouge accuracy --keep``) the runs already in out_dir/scaling_runs.json of the same
scene (scene_key: the config less seed and the settings the ladder sets) are kept and not run
again, so that seeds or rungs can be added to a ladder; the summary is over the requested
lambdas and seeds only, the file keeps every run.
"""

from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path

import numpy as np

from ..config import Config, build_config
from ..errors import ConfigError

QUANTITIES = ("static_strength", "stress_drop", "recurrence", "peak_velocity", "duration")


def scene_key(config: Config) -> str:
    """Fingerprint of the ladder's scene [hex]: the config without seed and the keys the ladder
    sets per run (numerics.stick_scaling, stick_inertial_max, threads); runs with the same key
    differ only by seed and lambda."""
    import hashlib

    data = config.to_dict()
    data.pop("seed", None)
    data["numerics"] = {k: v for k, v in data["numerics"].items()
                        if k not in ("stick_scaling", "stick_inertial_max", "threads")}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def kept_runs(path: Path, key: str) -> list[dict]:
    """The runs recorded in `path` (scaling_runs.json); ConfigError if one is of another scene."""
    runs = json.loads(Path(path).read_text()) if Path(path).exists() else []
    other = [f"lambda {r['lam']:g} seed {r['seed']}" for r in runs if r.get("scene") != key]
    if other:
        raise ConfigError(f"--keep: {path} holds runs of another scene or without a scene key "
                          f"({', '.join(other[:3])}{', ...' if len(other) > 3 else ''}); use another --out")
    return runs


def _run_rung(config: Config, packing, lam: float, out_dir: Path) -> dict:
    """One loading run from the compacted `packing` (a Checkpoint) at lambda; its slips and costs."""
    from ..io.layout import RunLayout
    from ..io.integrity import attr_value
    from ..io.runreader import RunReader
    from ..io.runwriter import RunFile
    from ..driver.phases import load_phase
    from ..driver.compaction import compact
    from ..driver.simulation import Simulation

    cfg = build_config(config.to_dict(), {"numerics.stick_scaling": float(lam), "numerics.stick_inertial_max": 0.1,
                                          "numerics.threads": 1})
    sim = Simulation(cfg, arrays=packing.state)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_load, end = sim.state.time, sim.state.time + cfg.run.duration
    writer = RunFile(RunLayout(out_dir).run_file, cfg, sim.dt, extra_attrs={
        "n_grains": sim.state.n, "width": sim.state.width, "wall_mass_per_length": sim.wall_mass_per_length,
        "load_start_time": t_load, "end_time": end}, threads=1)
    writer.append(sim.observe())
    step0, wall0 = sim.state.step, time.perf_counter()
    status, recorder = load_phase(sim, writer, out_dir, end, quiet=True, checkpoints=False)
    wall = time.perf_counter() - wall0
    steps = sim.state.step - step0
    writer.close(status)
    i_max, counts = float("nan"), {}
    with RunReader(out_dir) as run:                     # the columns and counts of stick scaling, if on
        series = run.series(("stick_scaling", "inertial_number"))
        if series["stick_scaling"] is not None:
            scaled = series["stick_scaling"] > 1.0
            i_max = float(np.nanmax(series["inertial_number"][scaled])) if scaled.any() else float("nan")
        counts = json.loads(attr_value(run.h5.attrs, "stick_scaling_counts", "{}"))
    return {"lam": float(lam), "status": status, "steps": int(steps), "wall": wall, "n": sim.state.n,
            "t_load": t_load, "duration": cfg.run.duration, "i_max": i_max, "counts": counts,
            "slips": [{k: getattr(s, k) for k in ("onset_time", "static_strength", "stress_drop", "peak_velocity",
                                                 "duration")} for s in recorder.slips]}


def slip_table(run: dict, transient: float) -> dict[str, np.ndarray]:
    """Per-quantity arrays of the slips of one run with onset after the transient; recurrence is
    the time since the previous slip's onset (the first slip has none)."""
    slips = run["slips"]
    t0 = run["t_load"] + transient * run["duration"]
    onsets = np.array([s["onset_time"] for s in slips])
    keep = onsets >= t0
    out = {q: np.array([s[q] for s in slips])[keep] for q in QUANTITIES if q != "recurrence"}
    rec = np.full(onsets.size, np.nan)
    rec[1:] = np.diff(onsets)
    out["recurrence"] = rec[keep][~np.isnan(rec[keep])]
    return out


def summarize(runs: list[dict], transient: float) -> dict:
    """The ladder table (module docstring) from the per-(lambda, seed) run dicts."""
    lams = sorted({r["lam"] for r in runs})
    by = {lam: [r for r in runs if r["lam"] == lam] for lam in lams}
    tables = {lam: [slip_table(r, transient) for r in by[lam]] for lam in lams}

    def pooled(lam, q):
        return np.concatenate([t[q] for t in tables[lam]]) if tables[lam] else np.zeros(0)

    ref = lams[0]
    cycle = float(np.mean(pooled(ref, "recurrence")))
    spread = {}
    for q in QUANTITIES:
        means = [float(np.mean(t[q])) for t in tables[ref] if t[q].size]
        spread[q] = float(np.std(means, ddof=1)) if len(means) > 1 else float("nan")
    rows = []
    for lam in lams:
        rs = by[lam]
        steps_per_t = np.mean([r["steps"] / r["duration"] for r in rs])
        wall_per_t = np.mean([r["wall"] / r["duration"] for r in rs])
        row = {"lambda": lam, "seeds": len(rs),
               "slips_per_seed": float(np.mean([t["stress_drop"].size for t in tables[lam]])),
               "grain_steps_per_cycle": float(rs[0]["n"] * steps_per_t * cycle),
               "wall_s_per_cycle": float(wall_per_t * cycle),
               "i_max": float(np.nanmax([r["i_max"] for r in rs])) if lam > 1 else float("nan"),
               "rollbacks": int(sum(r["counts"].get("rollbacks", 0) for r in rs)),
               "misses": int(sum(r["counts"].get("misses", 0) for r in rs)),
               "in_place": int(sum(r["counts"].get("in_place", 0) for r in rs))}
        ok = True
        for q in QUANTITIES:
            a, b = pooled(lam, q), pooled(ref, q)
            diff = float(np.mean(a) - np.mean(b)) if a.size and b.size else float("nan")
            ci = 1.96 * math.sqrt(np.var(a, ddof=1) / a.size + np.var(b, ddof=1) / b.size) \
                if a.size > 1 and b.size > 1 else float("nan")
            row[f"{q}_mean"] = float(np.mean(a)) if a.size else float("nan")
            row[f"{q}_diff"], row[f"{q}_ci95"], row[f"{q}_spread"] = diff, ci, spread[q]
            ok = ok and math.isfinite(diff) and abs(diff) <= spread[q]
        row["within_spread"] = bool(ok or lam == ref)
        rows.append(row)
    ref_steps = rows[0]["grain_steps_per_cycle"]
    for row in rows:
        row["speedup"] = ref_steps / row["grain_steps_per_cycle"]
    default = lams[0]
    for row in rows:
        if not row["within_spread"]:
            break
        default = row["lambda"]
    return {"rows": rows, "cycle": cycle, "default": default, "transient": transient}


def run_ladder(config: Config, lambdas: list[float], seeds: int, out_dir: Path, transient: float = 0.2,
               progress=None, keep: bool = False) -> dict:
    """Run the ladder (one run at a time) into out_dir/lam_<L>/seed_<S>; write scaling_ladder.json,
    scaling_ladder.csv and scaling_ladder.png; returns summarize()'s dict plus the runs (those
    summarized). `keep`: reuse the runs of out_dir/scaling_runs.json (module docstring)."""
    from ..io.checkpoint import snapshot_of
    from ..driver.compaction import compact
    from ..driver.simulation import Simulation

    out_dir = Path(out_dir)
    lambdas = sorted({float(v) for v in lambdas} | {1.0})
    key = scene_key(config)
    runs = kept_runs(out_dir / "scaling_runs.json", key) if keep else []
    done = {(r["lam"], r["seed"]) for r in runs}
    for k in range(seeds):
        seed = config.seed + k
        todo = [lam for lam in lambdas if (lam, seed) not in done]
        if not todo:
            continue
        cfg = build_config(config.to_dict(), {"seed": seed, "numerics.threads": 1, "numerics.stick_scaling": 1.0})
        sim = Simulation(cfg)
        compact(sim)
        packing = snapshot_of(sim)
        for lam in todo:
            r = _run_rung(cfg, packing, lam, out_dir / f"lam_{lam:g}" / f"seed_{seed}")
            r["seed"], r["scene"] = seed, key
            runs.append(r)
            if progress:
                progress(r)
            out_dir.mkdir(parents=True, exist_ok=True)
            (out_dir / "scaling_runs.json").write_text(json.dumps(runs, indent=1))
    wanted = {config.seed + k for k in range(seeds)}
    runs = sorted((r for r in runs if r["lam"] in lambdas and r["seed"] in wanted), key=lambda r: (r["seed"], r["lam"]))
    result = summarize(runs, transient)
    write_outputs(result, out_dir)
    result["runs"] = runs
    return result


def write_outputs(result: dict, out_dir: Path):
    out_dir = Path(out_dir)
    (out_dir / "scaling_ladder.json").write_text(json.dumps({k: v for k, v in result.items() if k != "runs"},
                                                            indent=1))
    rows = result["rows"]
    with open(out_dir / "scaling_ladder.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    from ..plots.scaling import plot_ladder

    plot_ladder(result, out_dir / "scaling_ladder.png")
