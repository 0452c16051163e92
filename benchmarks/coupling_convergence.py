"""Do the undrained pair metrics converge in the pressure grid at a fixed filter width?

For each seed: the demo scene's dry loading run (configs/demo.yaml at that seed), then every
non-transient slip with a checkpoint (at most --slips per seed) forked drained and undrained at
kappa_c = --perm on each grid spacing h of --grids (fluid.cell_size; fluid.filter_width fixed at
--width). The drained branch is dry, so one serves every grid. Per pair: the type, S_u - S_d, the
peak-velocity and stress-drop ratios and De_max, from each fork's pair.json.

Then, for each metric, the differences between the two finest grids on the same slip against the
spread between seeds (the standard deviation over the slips of all seeds, on the finest grid):
the coupling is converged for a metric when the grid difference is well below that spread.

Resumable: a finished loading run or fork is kept. Writes OUT/convergence.csv (one row per slip
and grid) and OUT/summary.csv, and prints the summary. Example (the validation page's table):

    .venv/bin/python benchmarks/coupling_convergence.py --seeds 1 2 --slips 5 --out runs/convergence \
        --figure docs/figures/convergence/pairs_on_two_grids.png
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
GOUGE = [sys.executable, "-c", "from gouge_cli.cli.main import main; main()"]
METRICS = ("strength_difference", "peak_velocity_ratio", "stress_drop_ratio", "deborah_max")


def gouge(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*GOUGE, *args], capture_output=True, text=True, cwd=REPO)


def loading_run(seed: int, out: Path) -> Path:
    run = out / f"seed_{seed}" / "loading"
    from gouge_cli.io.runreader import run_status

    if not (run / "run.h5").is_file() or run_status(run / "run.h5") != "finished":
        result = gouge("run", str(REPO / "configs" / "demo.yaml"), "--out", str(run), "--set", f"seed={seed}",
                       "--set", f"name=demo_seed{seed}", "--quiet", "--force")
        if result.returncode != 0:
            raise SystemExit(f"loading run of seed {seed} failed:\n{result.stdout}\n{result.stderr}")
    return run


def slips_to_fork(run: Path, count: int) -> list[int]:
    from gouge_cli.io.slipcatalog import slip_catalog

    numbers = [e.number for e in slip_catalog(run) if e.checkpoint]
    return numbers[1:count + 1]          # the first slip is the loading transient


def fork(run: Path, grid_dir: Path, slip: int, perm: float, width: float, h: float) -> dict:
    """pair.json's pair of slip `slip` forked on grid h (a copy of the loading run per grid)."""
    if not (grid_dir / "run.h5").is_file():
        shutil.copytree(run, grid_dir, ignore=shutil.ignore_patterns("forks", ".gouge.lock"))
    pair = grid_dir / "forks" / f"slip_{slip:03d}" / "pair.json"
    if not pair.is_file():
        result = gouge("restart", str(grid_dir), "--slip", str(slip), "--perm", f"{perm:g}", "--quiet",
                       "--set", f"fluid.filter_width={width:g}", "--set", f"fluid.cell_size={h:g}")
        if result.returncode != 0 or not pair.is_file():
            return {"status": f"failed: {(result.stdout + result.stderr).strip().splitlines()[-1:]}"}
    data = json.loads(pair.read_text())
    row = data["pairs"][0] if data.get("pairs") else {}
    value = {m: row.get(m) for m in METRICS}
    return {"status": "ok", "type": row.get("type"),
            **{m: float(v) if v is not None else float("nan") for m, v in value.items()}}


def figure(rows: list[dict], fine: float, finer: float, path: Path):
    """Each pair's metric on grid `fine` against grid `finer` (one panel per metric), the identity
    line, seeds by colour: points on the line are converged; the spread along it is the slips'."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {(int(r["seed"]), int(r["slip"]), float(r["h"])): r for r in rows if r["status"] == "ok"}
    fig, axes = plt.subplots(1, len(METRICS), figsize=(4 * len(METRICS), 3.8))
    for ax, m in zip(axes, METRICS):
        for seed in sorted({k[0] for k in by}):
            pts = [(float(by[(s, n, finer)][m]), float(by[(s, n, fine)][m])) for s, n, h in by
                   if s == seed and h == fine and (s, n, finer) in by]
            if pts:
                x, y = np.array(pts, float).T
                ax.plot(x, y, "o", label=f"seed {seed}")
        lo, hi = ax.get_xlim()
        lo, hi = min(lo, ax.get_ylim()[0]), max(hi, ax.get_ylim()[1])
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        ax.set_xlabel(f"h = {finer:g} d")
        ax.set_ylabel(f"h = {fine:g} d")
        ax.set_title(m, fontsize=10)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--slips", type=int, default=5, help="forked slips per seed")
    parser.add_argument("--grids", type=float, nargs="+", default=[1.5, 0.75], help="cell sizes h [d]")
    parser.add_argument("--width", type=float, default=3.0, help="filter width w [d]")
    parser.add_argument("--perm", type=float, default=1e-5)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=REPO / "runs" / "convergence")
    parser.add_argument("--figure", type=Path, help="also draw the pairs on the two finest grids here")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(args.jobs) as pool:
        runs = dict(zip(args.seeds, pool.map(lambda s: loading_run(s, args.out), args.seeds)))
        tasks = [(seed, slip, h) for seed in args.seeds for slip in slips_to_fork(runs[seed], args.slips)
                 for h in args.grids]
        results = list(pool.map(lambda t: fork(runs[t[0]], args.out / f"seed_{t[0]}" / f"h_{t[2]:g}", t[1],
                                               args.perm, args.width, t[2]), tasks))
    rows = [{"seed": s, "slip": n, "h": h, **r} for (s, n, h), r in zip(tasks, results)]
    with (args.out / "convergence.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, ["seed", "slip", "h", "status", "type", *METRICS])
        writer.writeheader()
        writer.writerows(rows)
    fine, finer = sorted(args.grids)[1], sorted(args.grids)[0]
    by = {(r["seed"], r["slip"], r["h"]): r for r in rows if r["status"] == "ok"}
    keys = sorted({(s, n) for s, n, h in by if (s, n, fine) in by and (s, n, finer) in by})
    summary = []
    types_same = sum(by[(s, n, fine)]["type"] == by[(s, n, finer)]["type"] for s, n in keys)
    print(f"{len(keys)} slips on both grids h = {fine:g} and {finer:g} (w = {args.width:g}, kappa_c = {args.perm:g}); "
          f"same pair type in {types_same}")
    for m in METRICS:
        diff = np.array([by[(s, n, fine)][m] - by[(s, n, finer)][m] for s, n in keys], float)
        values = np.array([by[k][m] for k in by if k[2] == finer], float)
        seed_means = [np.nanmean([by[k][m] for k in by if k[2] == finer and k[0] == s]) for s in args.seeds]
        entry = {"metric": m, "slips": len(keys), "median_abs_grid_difference": float(np.nanmedian(np.abs(diff))),
                 "max_abs_grid_difference": float(np.nanmax(np.abs(diff))) if diff.size else float("nan"),
                 "spread_over_slips": float(np.nanstd(values, ddof=1)) if values.size > 1 else float("nan"),
                 "spread_of_seed_means": float(np.nanstd(seed_means, ddof=1)) if len(seed_means) > 1 else float("nan"),
                 "same_type": types_same}
        summary.append(entry)
        print(f"  {m:20s} grid difference median {entry['median_abs_grid_difference']:.3g} max "
              f"{entry['max_abs_grid_difference']:.3g} | spread over slips {entry['spread_over_slips']:.3g}, "
              f"of seed means {entry['spread_of_seed_means']:.3g}")
    with (args.out / "summary.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, list(summary[0]))
        writer.writeheader()
        writer.writerows(summary)
    if args.figure is not None:
        figure(rows, fine, finer, args.figure)


if __name__ == "__main__":
    main()
