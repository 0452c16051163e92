#!/usr/bin/env python
"""Many-core measurement: gouge's thread scaling up to 16 threads, LAMMPS on the same rank
counts, and the throughput of several 2-thread runs side by side (as ``gouge campaign`` runs
them on one node, numba threads set by workflows.executors.worker_env).

    python benchmarks/many_core.py                      # 16-core machine, ~8 minutes
    OUT=/tmp/mc python benchmarks/many_core.py --sizes 2000 --threads 1,2 --concurrent 2 --seconds 4 \\
        --steps 200 --repeats 1                         # a quick check that it works

Run from the repository root (gouge importable). Results go to $OUT (default ./many_core_out):

1. ``gouge bench`` once, at --sizes on --threads (thread counts take turns within each repeat;
   the per-part profile on; no fluid), LAMMPS on the same rank counts where ``lmp`` is found
   (``gouge bench`` runs it, up to --lammps-max grains): bench.json and its printed tables,
   bench.txt. The bench records the CPU model, vector width, numba target and thread counts.
2. Runs side by side: one 2-thread run of the --concurrent-size scene alone, then --concurrent
   of them at once, then one alone again, each for --seconds of steady shear started together
   (every process first loads the kernels and the bench's pre-sheared state): concurrent.json.
3. many_core.json (everything) and summary.txt: rates, paired speed-up over one thread and
   per-part speed-ups (what does not scale), gouge / LAMMPS per rank count, the side-by-side
   aggregate against one run alone, and the two targets (16 threads >= 10x one thread at the
   largest size; --concurrent runs >= 6.5x one run's rate).

Time on 16 cores with a cold numba cache and no LAMMPS: ~1.5 min compiling, ~1 min preparing
the two scenes, ~2 min of bench, ~1.5 min side by side; LAMMPS adds ~15 s of set-up per rank
count and style at 10,000 grains (--lammps-max 0 or --no-lammps to skip it).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))      # this checkout's gouge_cli, also in the processes started below
DT, SKIN = 0.89, 0.2               # the bench scene's step and skin (gouge bench defaults)
CACHE = Path("runs/bench/cache")   # gouge bench's cache of pre-sheared states
SCALING_TARGET = 10.0              # 16 threads / 1 thread at the largest size
CONCURRENT_TARGET = 6.5            # aggregate of 8 two-thread runs / one run alone


# ---- measuring --------------------------------------------------------------------------------

def _env() -> dict:
    """This environment with this checkout first on PYTHONPATH."""
    path = os.environ.get("PYTHONPATH", "")
    return dict(os.environ, PYTHONPATH=str(REPO) + (os.pathsep + path if path else ""))


def run_bench(args, out: Path) -> dict:
    """One `gouge bench` invocation; its JSON (also written to out/bench.json)."""
    threads = [int(t) for t in args.threads.split(",")]
    env = dict(_env(), NUMBA_NUM_THREADS=str(max(threads)))
    cmd = [sys.executable, "-m", "gouge_cli.cli", "bench", "--sizes", args.sizes, "--threads", args.threads,
           "--steps", str(args.steps), "--repeats", str(args.repeats), "--perm", "0",
           "--lammps-max", str(args.lammps_max), "--json", str(out / "bench.json")]
    if args.no_lammps:
        cmd.append("--no-lammps")
    print("$", " ".join(cmd), flush=True)
    with open(out / "bench.txt", "w") as log:
        subprocess.run(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, check=True)
    return json.loads((out / "bench.json").read_text())


def worker(folder: Path, index: int, n_grains: int, threads: int, seconds: float):
    """One side-by-side run: the pre-sheared bench state on `threads` threads; says it is ready,
    waits for the go file, then steps for `seconds` and writes its rate."""
    from gouge_cli.studies.bench import prepare

    sim, start = prepare(n_grains, DT, SKIN, CACHE)
    sim.threads = threads
    sim.state.restore(start)
    sim.advance(20)                                   # kernels loaded, memory touched
    (folder / f"ready_{index}").touch()
    while not (folder / "go").exists():
        time.sleep(0.02)
    chunk = max(10, 200000 // n_grains)
    steps, wall0, t0 = 0, time.time(), time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        sim.advance(chunk)
        steps += chunk
    elapsed = time.perf_counter() - t0
    (folder / f"result_{index}.json").write_text(json.dumps({
        "index": index, "threads": threads, "n_grains": sim.state.n, "steps": steps, "seconds": elapsed,
        "rate": steps * sim.state.n / elapsed, "wall_start": wall0, "wall_end": wall0 + elapsed}))


def side_by_side(count: int, args, folder: Path) -> list[dict]:
    """`count` worker processes started together (campaign environment, 2 threads each)."""
    from gouge_cli.workflows.executors import worker_env

    folder.mkdir(parents=True, exist_ok=True)
    for f in folder.iterdir():
        f.unlink()
    env = dict(_env(), **worker_env(args.concurrent_threads))
    procs = [subprocess.Popen([sys.executable, __file__, "--worker", str(folder), "--index", str(i),
                               "--concurrent-size", str(args.concurrent_size),
                               "--concurrent-threads", str(args.concurrent_threads), "--seconds", str(args.seconds)],
                              env=env) for i in range(count)]
    deadline = time.time() + 1800                   # (a loaded machine starts processes slowly)
    while sum((folder / f"ready_{i}").exists() for i in range(count)) < count:
        if any(p.poll() not in (None, 0) for p in procs) or time.time() > deadline:
            for p in procs:
                p.kill()
            raise RuntimeError(f"side-by-side workers did not start ({folder})")
        time.sleep(0.05)
    (folder / "go").touch()
    for p in procs:
        if p.wait() != 0:
            raise RuntimeError(f"a side-by-side worker failed ({folder})")
    return [json.loads((folder / f"result_{i}.json").read_text()) for i in range(count)]


def run_concurrent(args, out: Path) -> dict:
    """One run alone, `args.concurrent` together, one alone again (the two alone runs bracket the
    crowded one, so that a drift of the machine shows)."""
    subprocess.run([sys.executable, __file__, "--prepare", "--concurrent-size", str(args.concurrent_size)], env=_env(),
                   check=True)
    result = {"n_grains": args.concurrent_size, "threads_per_run": args.concurrent_threads, "seconds": args.seconds,
              "runs": args.concurrent}
    result["alone_before"] = side_by_side(1, args, out / "side_by_side")
    result["together"] = side_by_side(args.concurrent, args, out / "side_by_side")
    result["alone_after"] = side_by_side(1, args, out / "side_by_side")
    (out / "concurrent.json").write_text(json.dumps(result, indent=2))
    return result


# ---- summarising (pure functions of the JSON; tests/studies/test_many_core.py) ------------------

def _by_int(mapping: dict) -> dict[int, float]:
    """JSON object keys back to ints."""
    return {int(k): v for k, v in mapping.items()}


def scaling_table(bench: dict) -> list[dict]:
    """Per size and thread count: gouge's median rate, its paired speed-up over the fewest threads
    (median of the per-repeat ratios), the machine probe's, and LAMMPS per style at that rank count
    with gouge / LAMMPS."""
    rows = []
    scaling = {s["n_grains"]: s for s in bench.get("scaling", [])}
    lammps = {(r["code"].removeprefix("lammps-"), r["n_grains"], r["threads"]): r["rate_median"]
              for r in bench["rows"] if r["code"].startswith("lammps-")}
    gouge = [r for r in bench["rows"] if r["code"] == "gouge"]
    for r in gouge:
        n, t = r["n_grains"], r["threads"]
        paired = _by_int(scaling.get(n, {}).get("paired_ratio", {}))
        stream = _by_int(scaling.get(n, {}).get("machine_stream_ratio", {}))
        fewest = min(q["threads"] for q in gouge if q["n_grains"] == n)
        row = {"n_grains": n, "threads": t, "rate": r["rate_median"], "identical": r["identical_to_1_thread"],
               "speedup": 1.0 if t == fewest else paired.get(t), "machine_speedup": 1.0 if t == fewest else stream.get(t),
               "lammps": {}}
        for (style, ln, lt), rate in lammps.items():
            if (ln, lt) == (n, t):
                row["lammps"][style] = {"rate": rate, "gouge_over": r["rate_median"] / rate}
        rows.append(row)
    return rows


def part_scaling(bench: dict) -> list[dict]:
    """Per size and thread count: each profiled part [us per step] and its speed-up over the
    fewest threads profiled at that size (what does not scale)."""
    parts = ("contact_forces", "law_pass", "sum_pass", "kick_drift", "rebuild_per_step", "renumber_per_step",
             "whole_step")
    prof = bench.get("profile_us", [])
    out = []
    for p in prof:
        base = min((q for q in prof if q["n_grains"] == p["n_grains"]), key=lambda q: q["threads"])
        out.append({"n_grains": p["n_grains"], "threads": p["threads"],
                    "us": {k: p[k] for k in parts if k in p},
                    "speedup": {k: base[k] / p[k] for k in parts if k in p and p[k] > 0}})
    return out


def concurrent_summary(conc: dict) -> dict:
    """Aggregate rate of the runs together (sum of their rates; they ran over the same window)
    against one run alone (mean of the runs before and after)."""
    alone = [r["rate"] for key in ("alone_before", "alone_after") for r in conc.get(key, [])]
    together = [r["rate"] for r in conc["together"]]
    starts = [r["wall_start"] for r in conc["together"]]
    ends = [r["wall_end"] for r in conc["together"]]
    alone_rate = statistics.fmean(alone)
    return {"runs": len(together), "threads_per_run": conc["threads_per_run"], "n_grains": conc["n_grains"],
            "alone_rates": alone, "alone_rate": alone_rate, "together_rates": together,
            "aggregate_rate": sum(together), "aggregate_over_alone": sum(together) / alone_rate,
            "slowest_over_alone": min(together) / alone_rate,
            "overlap": (min(ends) - max(starts)) / max(max(ends) - min(starts), 1e-12)}


def targets(table: list[dict], conc: dict | None) -> dict:
    """The issue's two figures where measured: speed-up at the largest thread count of the largest
    size (target for 16 threads), and the side-by-side aggregate over one run (target for 8 runs)."""
    out = {}
    largest = max((r["n_grains"] for r in table), default=None)
    rows = [r for r in table if r["n_grains"] == largest and r["speedup"] is not None]
    if rows:
        top = max(rows, key=lambda r: r["threads"])
        out["scaling"] = {"n_grains": largest, "threads": top["threads"], "speedup": top["speedup"],
                          "target": SCALING_TARGET if top["threads"] == 16 else None}
    if conc:
        out["concurrent"] = {"runs": conc["runs"], "ratio": conc["aggregate_over_alone"],
                             "target": CONCURRENT_TARGET if conc["runs"] == 8 else None}
    return out


def summarize(bench: dict, conc: dict | None) -> tuple[dict, str]:
    """(many_core.json content, summary text)."""
    cpu = bench.get("provenance", {}).get("cpu", {})
    table = scaling_table(bench)
    parts = part_scaling(bench)
    side = concurrent_summary(conc) if conc else None
    goals = targets(table, side)
    lines = [f"CPU: {cpu.get('model', '?')}, {bench.get('machine', {}).get('cpus', '?')} cores, "
             f"{cpu.get('vector_width_bits', '?')}-bit vectors, numba target {cpu.get('numba_target', '?')}, "
             f"numba threads {bench.get('machine', {}).get('numba_threads', '?')}",
             f"bench: dt {bench.get('dt')}, skin {bench.get('skin')}; grain-steps/s (median of repeats); speed-up: "
             "median of per-repeat ratios to 1 thread (machine: the streaming probe's)", ""]
    styles = sorted({s for r in table for s in r["lammps"]})
    head = f"{'N':>7} {'thr':>4} {'gouge':>9} {'speedup':>8} {'machine':>8} {'same bits':>9}"
    head += "".join(f" {'lmp-' + s:>13} {'gouge/' + s:>10}" for s in styles)
    lines.append(head)
    for r in table:
        line = (f"{r['n_grains']:>7} {r['threads']:>4} {r['rate']:>9.3g} {_num(r['speedup'], '.2f', 'x'):>8} "
                f"{_num(r['machine_speedup'], '.2f', 'x'):>8} {str(r['identical']):>9}")
        for s in styles:
            lam = r["lammps"].get(s)
            line += f" {_num(lam and lam['rate'], '.3g'):>13} {_num(lam and lam['gouge_over'], '.2f'):>10}"
        lines.append(line)
    if parts:
        names = list(parts[0]["us"])
        lines += ["", "us per step by part (best of 3 x 50 calls), speed-up over the fewest threads in brackets",
                  f"{'N':>7} {'thr':>4} " + " ".join(f"{k:>22}" for k in names)]
        for p in parts:
            lines.append(f"{p['n_grains']:>7} {p['threads']:>4} " + " ".join(
                f"{p['us'][k]:>12.1f} ({_num(p['speedup'].get(k), '.2f', 'x'):>6})" for k in names))
    if side:
        lines += ["", f"side by side: {side['runs']} runs of {side['n_grains']} grains on {side['threads_per_run']} "
                  f"threads each: aggregate {side['aggregate_rate']:.3g} grain-steps/s against "
                  f"{side['alone_rate']:.3g} for one run alone ({', '.join(f'{v:.3g}' for v in side['alone_rates'])}): "
                  f"{side['aggregate_over_alone']:.2f}x; slowest run {side['slowest_over_alone']:.2f} of alone; "
                  f"windows overlap {side['overlap']:.0%}"]
    lines.append("")
    for name, g in goals.items():
        value = g.get("speedup", g.get("ratio"))
        what = (f"{g['threads']} threads / 1 at {g['n_grains']} grains" if name == "scaling"
                else f"{g['runs']} runs side by side / one alone")
        verdict = "" if g["target"] is None else (" (target {:.1f}x: {})".format(
            g["target"], "met" if value >= g["target"] else "SHORT"))
        lines.append(f"{what}: {value:.2f}x{verdict}")
    record = {"cpu": cpu, "machine": bench.get("machine"), "scaling": table, "parts": parts, "side_by_side": side,
              "targets": goals, "bench_provenance": bench.get("provenance")}
    return record, "\n".join(lines) + "\n"


def _num(value, fmt: str, suffix: str = "") -> str:
    return "-" if value is None else format(value, fmt) + suffix


# ---- command line -------------------------------------------------------------------------------

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="10000,40000")
    ap.add_argument("--threads", default="1,2,4,8,16")
    ap.add_argument("--steps", type=int, default=3000, help="gouge bench --steps (fewer above 10,000 grains)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--lammps-max", type=int, default=10000, help="largest N timed in LAMMPS")
    ap.add_argument("--no-lammps", action="store_true")
    ap.add_argument("--concurrent", type=int, default=8, help="runs side by side (0: skip)")
    ap.add_argument("--concurrent-threads", type=int, default=2)
    ap.add_argument("--concurrent-size", type=int, default=None, help="grains per side-by-side run (default: the "
                    "smallest of --sizes)")
    ap.add_argument("--seconds", type=float, default=15.0, help="steady shear timed per side-by-side run")
    ap.add_argument("--summarize-only", action="store_true", help="re-read $OUT's JSON and write the summary")
    ap.add_argument("--reuse-bench", action="store_true", help="take $OUT/bench.json from an earlier run, measure "
                    "the rest")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--index", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--prepare", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.concurrent_size is None:
        args.concurrent_size = min(int(v) for v in args.sizes.split(","))
    if args.worker:
        return worker(args.worker, args.index, args.concurrent_size, args.concurrent_threads, args.seconds)
    if args.prepare:
        from gouge_cli.studies.bench import prepare
        prepare(args.concurrent_size, DT, SKIN, CACHE)
        return None
    out = Path(os.environ.get("OUT") or "many_core_out")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    if args.summarize_only:
        bench = json.loads((out / "bench.json").read_text())
        conc_file = out / "concurrent.json"
        conc = json.loads(conc_file.read_text()) if conc_file.is_file() else None
    else:
        bench = json.loads((out / "bench.json").read_text()) if args.reuse_bench else run_bench(args, out)
        print(f"bench done after {time.time() - t0:.0f} s", flush=True)
        conc = run_concurrent(args, out) if args.concurrent > 0 else None
    record, text = summarize(bench, conc)
    record["seconds"] = time.time() - t0
    (out / "many_core.json").write_text(json.dumps(record, indent=2))
    (out / "summary.txt").write_text(text)
    print(text + f"({record['seconds']:.0f} s; results in {out})")
    return None


if __name__ == "__main__":
    main()
