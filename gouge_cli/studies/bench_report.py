"""`gouge bench`'s printed report: the tables and lines of a :class:`~gouge_cli.studies.bench.BenchResult`
(rates in grain-steps/s, parts in microseconds per call), for the CLI to print in order."""

from __future__ import annotations

from pathlib import Path

from rich.table import Table

from ..io.layout import perm_text
from .bench import BenchResult


def bench_report(r: BenchResult, json_path: Path) -> list[str | Table]:
    """The report in print order: machine, rates table, LAMMPS, scaling, profile and footprint
    tables, allocations, fluid, Run 24 projection, memory."""
    prov = r.provenance
    items: list[str | Table] = [
        f"measured on: {prov['cpu']['model']} ({prov['cpu']['vector_width_bits']}-bit vectors: "
        f"{' '.join(prov['cpu']['vector_features'])}; numba target {prov['cpu']['numba_target']}, "
        f"features {r.machine.get('numba_cpu_features', 'host')}), "
        f"{r.machine['cpus']} cores; numpy {prov['libraries']['numpy']}, numba "
        f"{prov['libraries']['numba']}, llvmlite {prov['libraries']['llvmlite']}",
        _rates(r)]
    items += _lammps(r) + _scaling(r)
    if r.profile_us:
        items.append(_profile(r))
        items.append(_per_grain(r))
    if r.footprint:
        items.append(_footprint(r))
    for a in r.allocations:
        per = "unavailable" if a["per_step"] is None else f"{a['per_step']:g}"
        items.append(f"numba runtime allocations per step, N {a['n_grains']}, {a['threads']} thread(s): {per}")
    items += _fluid(r) + _run24(r)
    items.append(f"peak RSS {r.peak_rss_mb:.0f} MB; results in {json_path}")
    return items


def _rates(r: BenchResult) -> Table:
    table = Table(title=f"grain-steps per second (dt {r.dt}, skin {r.skin}; steady shear)")
    for col in ("code", "N", "threads", "steps", "min", "median", "max", "bytes/grain", "bitwise = 1 thread",
                "gouge / this"):
        table.add_column(col, justify="right")
    ours = {(row.n_grains, row.threads): row.rate_median for row in r.rows if row.code == "gouge"}
    for row in r.rows:
        mine = ours.get((row.n_grains, row.threads))
        ratio = f"{mine / row.rate_median:.2f}" if mine and row.code != "gouge" else ""
        table.add_row(row.code, str(row.n_grains), str(row.threads), str(row.steps), f"{row.rate_min:.3g}",
                      f"{row.rate_median:.3g}", f"{row.rate_max:.3g}",
                      f"{row.bytes_per_grain:.0f}" if row.bytes_per_grain else "",
                      {None: "", True: "yes", False: "NO"}[row.identical_to_1_thread], ratio)
    return table


def _lammps(r: BenchResult) -> list[str]:
    if r.lammps.get("missing"):
        reasons = sorted({m["reason"] for m in r.lammps["missing"]})
        sizes = sorted({m["n_grains"] for m in r.lammps["missing"]})
        return [f"LAMMPS rows missing (N {', '.join(map(str, sizes))}): {'; '.join(reasons)}"]
    if not r.lammps.get("requested", True):
        return ["LAMMPS not timed (--no-lammps)"]
    return []


def _scaling(r: BenchResult) -> list[str]:
    lines = []
    for s in r.scaling:
        for t, ratio in s["paired_ratio"].items():
            lines.append(f"N {s['n_grains']}: {t} threads / fewest, median of the per-repeat ratios (thread counts "
                         f"take turns within each repeat): {ratio:.2f}x")
            machine = s.get("machine_stream_ratio", {}).get(t)
            if machine:
                lines.append(f"  the machine's own ratio in the same repeats, for a loop streaming the same "
                             f"{s['probe_bytes'] / 1e6:.1f} MB on {t} threads with nothing shared (kernels.probe): "
                             f"{machine:.2f}x; gouge reaches {ratio / machine:.0%} of it")
    for t in sorted({row.threads for row in r.rows if row.code == "gouge"}):
        rates = [row.rate_median for row in r.rows if row.code == "gouge" and row.threads == t]
        if len(rates) > 1:
            lines.append(f"{t} thread(s): fastest / slowest size {max(rates) / min(rates):.2f}")
    return lines


def _profile(r: BenchResult) -> Table:
    prof = Table(title="microseconds per step, by part (best of 3 x 50 calls)")
    for col in ("N", "threads", "contact pass", "(law", "sum)", "kick pass", "rebuild (each)", "steps/rebuild",
                "rebuild/step", "renumber (each)", "renumber/step", "whole step"):
        prof.add_column(col, justify="right")
    for p in r.profile_us:
        prof.add_row(str(p["n_grains"]), str(p["threads"]), f"{p['contact_forces']:.0f}", f"{p['law_pass']:.0f}",
                     f"{p['sum_pass']:.0f}", f"{p['kick_drift']:.0f}", f"{p['rebuild_each']:.0f}",
                     f"{p['steps_per_rebuild']:.0f}", f"{p['rebuild_per_step']:.0f}", f"{p['renumber_each']:.0f}",
                     f"{p['renumber_per_step']:.1f}", f"{p['whole_step']:.0f}")
    return prof


def _per_grain(r: BenchResult) -> Table:
    """The profile per grain: ns, and cycles at the clock /proc/cpuinfo gives (nominal on a VM; no
    cycle counter is read), so that CPUs can be compared part by part."""
    mhz = r.machine.get("cpu_mhz")
    unit = f"ns (cycles at {mhz / 1e3:.2f} GHz)" if mhz else "ns"
    table = Table(title=f"per grain and step, by part: {unit}")
    parts = (("contact pass", "contact_forces"), ("law", "law_pass"), ("sum", "sum_pass"),
             ("kick pass", "kick_drift"), ("rebuild/step", "rebuild_per_step"), ("whole step", "whole_step"))
    for col in ("N", "threads") + tuple(name for name, _ in parts):
        table.add_column(col, justify="right")
    for p in r.profile_us:
        cells = []
        for _, key in parts:
            ns = p[key] * 1e3 / p["n_grains"]
            cells.append(f"{ns:.1f} ({ns * mhz / 1e3:.0f})" if mhz else f"{ns:.1f}")
        table.add_row(str(p["n_grains"]), str(p["threads"]), *cells)
    return table


def _footprint(r: BenchResult) -> Table:
    own = {p["n_grains"]: p["contact_forces"] * 1e3 / p["n_grains"] for p in r.profile_us if p["threads"] == 1}
    big = r.footprint[0]["of_n_grains"]
    foot = Table(title=f"contact pass, 1 thread, ns per grain: the first m grains of the {big:,}-grain "
                 "packing (same rows, smaller working set) and the m-grain packing itself")
    for col in ("m", "pairs/grain", "working set MB", f"first m of {big:,}", "own packing"):
        foot.add_column(col, justify="right")
    for f in r.footprint:
        m = f["first_grains"]
        foot.add_row(f"{m:,}", f"{f['pairs_per_grain']:.2f}", f"{f['working_set_mb']:.2f}",
                     f"{f['ns_per_grain']:.1f}", f"{own[m]:.1f}" if m in own else "")
    return foot


def _fluid(r: BenchResult) -> list[str]:
    lines = []
    for f in r.fluid_profile_us:
        solve = "one explicit step" if f["explicit"] else f"{f['cg_iterations']:.0f} CG iterations"
        lines.append(f"one fluid update (N {f['n_grains']}, grid {f['grid'][0]}x{f['grid'][1]}, dt {f['dt']:.3g}), "
                     f"{f['threads']} thread(s), best of 3 x 30 calls: deposit {f['deposit']:.0f} us, grid solve "
                     f"{f['solve']:.0f} us (solver {f['solver']}: {solve}; on one thread: a run shares it), drag {f['drag']:.0f} us, "
                     f"together {f['update']:.0f} us")
    for f in r.fluid:
        lines.append(f"undrained (kappa_c {perm_text(f['permeability'])}, solver {f['solver']}, "
                     f"{100 * f['explicit_fraction']:.0f} % explicit steps, grid {f['grid'][0]}x{f['grid'][1]}, "
                     f"dt {f['dt']:.3g}, fluid update every {f['fluid_interval_steps']} steps), N {f['n_grains']}, "
                     f"{f['threads']} thread(s): {f['rate_undrained']:.3g} vs dry {f['rate_dry']:.3g} grain-steps/s, "
                     f"fluid share of a step {100 * f['fluid_share_paired']:.1f} % (median of the shares within each "
                     f"repeat, the two runs back to back; {100 * f['fluid_share']:.1f} % from the medians, "
                     f"{100 * f['fluid_share_best']:.1f} % from the fastest repeats)")
    return lines


def _run24(r: BenchResult) -> list[str]:
    r24 = r.run24
    if not r24:
        return []
    lines = [f"thesis Run 24 ({r24['n_grains']} grains, dt {r24['dt']:.3g} t0), {t} thread(s) at {v['rate']:.3g} "
             f"grain-steps/s: one loading cycle ({r24['cycle_t0']:.2g} t0) {v['cycle_hours']:.1f} h, one slip "
             f"({r24['slip_t0']:.3g} t0) {v['slip_minutes']:.1f} min" for t, v in r24["by_threads"].items()]
    for lam, v in r24.get("stick_scaling", {}).items():      # stick scaling: projected cycle
        hours = ", ".join(f"{h:.1f} h on {t} thread(s)" for t, h in v["cycle_hours"].items())
        lines.append(f"  with numerics.stick_scaling {float(lam):g}{' (chosen by the ladder)' if v['default'] else ''}: "
                     f"{v['step_ratio']:.2f}x fewer steps per cycle (stick_scaling.cycle_steps): {hours}")
    if "stick_scaling_cap" in r24:
        lines.append(f"  stick scaling's cap (lead, slip and quiet window at true inertia): "
                     f"{r24['stick_scaling_cap']:.1f}x")
    return lines
