"""The Python API (gouge_cli.api) against the run files and the CLI's outputs, on a tiny real run
forked before one slip: series and snapshots equal the HDF5 contents with units and
descriptions, the slip table equals `gouge slips --json` and `gouge analyze`'s CSV files, a pair
equals pair.json, opening changes no byte, a run in progress opens, a damaged file gives the CLI's error."""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import matplotlib
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

matplotlib.use("Agg")

import gouge_cli as gouge  # noqa: E402
from gouge_cli import api  # noqa: E402
from gouge_cli.analysis.catalog import CATALOG_COLUMNS  # noqa: E402
from gouge_cli.analysis.forkpairs import PAIR_COLUMNS  # noqa: E402
from gouge_cli.cli.main import app  # noqa: E402
from gouge_cli.errors import EXIT_BAD_INPUT, AnalysisError, NotARunError  # noqa: E402
from gouge_cli.units import pint_unit, si_of, unit_sizes  # noqa: E402
from slipping import TINY  # noqa: E402
from factories import fork_at  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENE = dict(TINY, name="tiny_api")      # tests/plots' scene: 2 or more slips for any GOUGE_TEST_SEED_OFFSET
PERM = 1e-3
runner = CliRunner()


def gouge_cli(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def forked(tiny_run, tmp_path_factory):
    """The tiny scene of tests/plots, forked before its first slip with a checkpoint (drained + one
    undrained branch writing snapshots with a pressure grid); the packing found through
    tests/slipping.py, so that it slips at every GOUGE_TEST_SEED_OFFSET."""
    _, out, numbers = tiny_run.copy(tmp_path_factory.mktemp("api"))    # any seed offset
    slip = numbers[0]
    result = gouge_cli("restart", out, "--slip", slip, "--perm", PERM, "--set", "output.snapshot_interval=1000",
                       "--quiet")
    assert result.exit_code == 0, result.output
    return out, slip


def _same(a, b, rel=1e-12) -> bool:
    """Equal numbers (NaN and None alike), strings and bools."""
    if a is None or (isinstance(a, float) and math.isnan(a)):
        return b is None or (isinstance(b, float) and math.isnan(b)) or b == ""
    if isinstance(a, (bool, np.bool_)) or isinstance(b, (bool, np.bool_)):
        return bool(a) == (b in (True, "True", "true")) if isinstance(b, str) else bool(a) == bool(b)
    if isinstance(a, (int, float, np.integer, np.floating)):
        return math.isclose(float(a), float(b), rel_tol=rel, abs_tol=0.0)
    return str(a) == str(b)


def test_package_names_the_api():
    for name in ("open_run", "open_study", "open_campaign", "run", "restart", "study"):
        assert getattr(gouge, name) is getattr(api, name)
    with pytest.raises(AttributeError):
        gouge.no_such_name


def test_series_equals_the_file_with_units_and_lazy(forked):
    out, _ = forked
    run = gouge.open_run(out)
    ds = run.series
    with h5py.File(out / "run.h5", "r") as h5:
        g = h5["series"]
        assert set(ds.data_vars) == set(g) - {"time"}
        for name, var in ds.data_vars.items():
            assert not var.variable._in_memory, f"{name} was read on opening"
            assert var.attrs["units"] == pint_unit(g[name].attrs["unit"])          # '-' as pint's '1'
            assert var.attrs["description"] == g[name].attrs["description"]
            assert var.attrs["long_name"] == name.replace("_", " ")          # short, for plot labels (issue 60)
            assert var.attrs["description"]
            np.testing.assert_array_equal(var.values, g[name][...])
        clock = g["time"][...]
        offset = clock[0] - g["load_time"][0]
        scales = json.loads(h5.attrs["scales"])
    np.testing.assert_array_equal(ds["clock"].values, clock)
    np.testing.assert_allclose(ds["time"].values, clock - offset, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds["time_s"].values, (clock - offset) * scales["time_s"], rtol=1e-12)
    for name in ("time", "time_s", "clock"):
        assert ds[name].attrs["units"] and ds[name].attrs["description"]
    assert ds["time"].values[0] == pytest.approx(0.0, abs=1e-9)
    part = ds["wall_vx"].isel(time=slice(5, 50, 3)).values        # a lazy slice reads that slice only
    np.testing.assert_array_equal(part, ds["wall_vx"].values[5:50:3])
    assert run.config.loading.spring_constant == SCENE["loading"]["spring_constant"]
    assert run.provenance["final_state_hash"] and "libraries" in run.provenance
    assert run.status == "finished" and run.scales["time_s"] == scales["time_s"]
    assert ds.attrs["scales"] == run.scales                              # a dict, as run.scales


def test_si_view_of_series_and_slips(forked):
    """to_si: one call gives a series or the slip table in SI, by the run's scales; the SI columns the
    catalog already holds agree; dimensionless values and words are left alone."""
    out, _ = forked
    run = gouge.open_run(out)
    si = run.to_si(run.slips)
    units = si.attrs["units"]
    assert units["onset_time"] == "s" and units["slip"] == "m" and units["static_strength"] == "1"
    np.testing.assert_allclose(si["onset_time"], si["onset_time_s"], rtol=1e-12)
    np.testing.assert_allclose(si["slip"], si["slip_m"], rtol=1e-12)
    np.testing.assert_array_equal(si["static_strength"], run.slips["static_strength"])
    assert list(si["fit_verdict"]) == list(run.slips["fit_verdict"])
    series = run.to_si(run.series[["wall_shear_stress", "wall_vx"]])
    assert series["wall_shear_stress"].attrs["units"] == "Pa" and series["wall_vx"].attrs["units"] == "m / s"
    np.testing.assert_allclose(series["wall_shear_stress"], run.series["wall_shear_stress"] * run.scales["stress_pa"])
    np.testing.assert_allclose(series["time"], run.series["time_s"], rtol=1e-12)
    one = run.to_si(run.series["tau_over_sigma"])
    assert one.attrs["units"] == "1" and one.name == "tau_over_sigma"
    factor, unit = si_of("E d^3", unit_sizes(run.scales, 1.0, 1.0))
    assert unit == "Pa * m**3" and factor == pytest.approx(run.scales["stress_pa"] * run.scales["length_m"] ** 3)
    assert si_of("1/t0", unit_sizes(run.scales, 1.0, 1.0))[1] == "1 / s" and si_of("MPa", unit_sizes(run.scales)) is None


def _written_units(out: Path, tmp_path: Path) -> dict[str, str]:
    """Every unit string in the run's files (run.h5 after `gouge analyze`, fork branches, checkpoints)
    and in the API's attrs (series, slips, snapshot, pair, study), by where it was found."""
    import shutil

    copy = tmp_path / "units_copy"
    shutil.copytree(out, copy)
    assert gouge_cli("analyze", copy).exit_code == 0
    found: dict[str, str] = {}

    def visit(path: Path, name: str, obj) -> None:
        if "unit" in obj.attrs:
            found[f"{path.name}:{name}:unit"] = str(obj.attrs["unit"])
        if "attribute_units" in obj.attrs:
            for key, (unit, _) in json.loads(obj.attrs["attribute_units"]).items():
                found[f"{path.name}:{name}@{key}"] = unit

    files = [copy / "run.h5", *copy.glob("checkpoints/*.h5"), *copy.glob("forks/*/*/run.h5")]
    assert len(files) >= 4 and any("analysis" in h5py.File(f, "r") for f in files[:1])
    for path in files:
        with h5py.File(path, "r") as h5:
            visit(path, "/", h5)
            h5.visititems(lambda name, obj, path=path: visit(path, name, obj))
    run = gouge.open_run(copy)
    slip = min(run.forks)
    for label, ds in (("series", run.series), ("snapshot", run.snapshot(-1)),
                      ("pair", run.pair(slip, PERM).series), ("wet", run.pair(slip, PERM).undrained.snapshot(0))):
        found.update({f"{label}:{k}": v.attrs["units"] for k, v in ds.variables.items() if "units" in v.attrs})
        assert "units" not in ds.attrs                 # a unit string, not the prose of the unit system
    for label, df in (("slips", run.slips), ("study", gouge.open_study(copy))):
        found.update({f"{label}:{k}": v for k, v in df.attrs["units"].items()})
    return found


def test_every_unit_written_is_made_of_the_units_table(forked, tmp_path):
    """Without pint: every unit string a run's files and the API write is '1', an SI symbol or a
    product of powers of gouge_cli.units.SCALE_UNITS (a list per element for mixed vectors)."""
    from gouge_cli.units import SCALE_UNITS, SI_SYMBOLS, unit_factors

    found = _written_units(forked[0], tmp_path)
    assert len(found) > 100
    for where, unit in found.items():
        for part in unit.split(","):
            factors = unit_factors(part)
            assert factors is not None and part.strip() not in ("-", ""), (where, unit)
            assert all(name in SCALE_UNITS or name in SI_SYMBOLS for name, _ in factors), (where, unit)


def test_pint_reads_every_unit_written_with_the_runs_definitions(forked, tmp_path):
    """pint (test extra): the run's registry parses every unit string written, a quantity converts to
    SI as to_si does, and pint-xarray quantifies the series with it (the units page's recipe)."""
    import pint
    import pint_xarray  # noqa: F401  (registers the .pint accessor)
    from gouge_cli.units import pint_definitions

    run = gouge.open_run(forked[0])
    registry = run.pint_registry()
    for where, unit in _written_units(forked[0], tmp_path).items():
        for part in unit.split(","):
            assert isinstance(registry.parse_units(part.strip()), pint.Unit), where
    for unit in ("E d^3", "1/t0", "rho_s d^2", "V_s", "sigma", "m_b", "d^2"):
        factor, si = si_of(unit, unit_sizes(run.scales, run.info.V_s, run.info.sigma, run.info.m_b))
        assert registry.Quantity(1.0, pint_unit(unit)).to(si).magnitude == pytest.approx(factor, rel=1e-12), unit
    assert registry.Quantity(1.0, "d_grain").to("mm").magnitude == pytest.approx(run.scales["length_m"] * 1e3)
    assert registry.Quantity(1.0, "d").to("h").magnitude == 24          # pint's day is left alone
    own = pint.UnitRegistry()                                   # the text alone, in a registry of one's own
    own.load_definitions(pint_definitions(run.scales).splitlines())
    force = own.Quantity(2.0, "E d_grain^2").to("N").magnitude
    assert force == pytest.approx(2 * run.scales["stress_pa"] * run.scales["length_m"] ** 2)
    assert "V_s" not in pint_definitions(run.scales) and math.isnan(unit_sizes(run.scales)["sigma_n"])
    quantified = run.series.pint.quantify(unit_registry=registry)
    assert quantified["wall_x"].data.units == registry.Unit("d_grain")
    assert quantified["wall_x"].pint.to("m").data.magnitude[-1] == pytest.approx(
        float(run.series["wall_x"][-1]) * run.scales["length_m"], rel=1e-12)


def test_plain_pint_never_misreads_a_unit_written(forked, tmp_path):
    """Every unit string gouge writes is refused by a plain pint registry or read with the dimension
    of gouge's registry: none silently becomes another quantity (a bare 'd' read as a day, 'sigma'
    as the Stefan-Boltzmann constant)."""
    import pint

    plain, own = pint.UnitRegistry(), gouge.open_run(forked[0]).pint_registry()
    refused = 0
    for where, unit in _written_units(forked[0], tmp_path).items():
        for part in unit.split(","):
            try:
                read = plain.parse_units(part.strip())
            except (pint.errors.UndefinedUnitError, pint.errors.DefinitionSyntaxError, ValueError):
                refused += 1
                continue
            assert read.dimensionality == own.parse_units(part.strip()).dimensionality, (where, part)
    assert refused > 10                                 # the scale units themselves are refused, not misread
    for notation in ("d", "sigma"):                     # what the tables say, and what pint would make of it
        assert plain.parse_units(notation).dimensionality != own.parse_units(pint_unit(notation)).dimensionality


def test_slips_equal_cli_json_and_analyze_csv(forked, tmp_path):
    out, _ = forked
    df = gouge.open_run(out).slips
    cli = json.loads(gouge_cli("slips", out, "--json").output)
    assert len(df) == len(cli) >= 1
    assert df.index.name == "number" and "number" not in df.columns
    for entry, (number, row) in zip(cli, df.iterrows()):
        assert number == entry["number"]
        assert _same(row["onset_time"], entry["onset_time"], 1e-9)      # both since loading began
        assert _same(row["end_time"], entry["end_time"], 1e-9)
        for key in ("duration", "static_strength", "stress_drop", "peak_velocity_over_Vs", "slip"):
            assert _same(row[key], entry[key]), key
        assert row["checkpoint"] == entry["checkpoint"]
        assert Path(row["checkpoint_path"]).is_file()
    assert set(df.attrs["units"]) == set(df.columns) and df.attrs["units"]["onset_time"] == "t0"
    copy = tmp_path / "copy"           # `gouge analyze` writes into the run: a copy keeps the fixture as it is
    import shutil

    shutil.copytree(out, copy)
    assert gouge_cli("analyze", copy).exit_code == 0
    with open(copy / "analysis" / "catalog.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for csv_row, (_, row) in zip(rows, df.reset_index().iterrows()):
        for col in CATALOG_COLUMNS:
            if isinstance(row[col], str) or row[col] is None:
                assert str(row[col] or "") == csv_row[col], col
            else:
                assert _same(row[col], float(csv_row[col]) if csv_row[col] != "" else None), col
    with open(copy / "analysis" / "fits.csv", newline="") as fh:
        fits = list(csv.DictReader(fh))
    for fit, (_, row) in zip(fits, df.iterrows()):
        assert _same(row["fit_r2"], float(fit["r2"])) and _same(row["m_eff_over_m_b"], float(fit["m_eff_over_m_b"]))
        assert row["fit_verdict"] == fit["verdict"]
        assert row["fit_ok"] == (fit["success"] == "True")
        assert _same(row["fit_half_period"], float(fit["half_period"]))


def test_pair_equals_pair_json(forked):
    out, slip = forked
    run = gouge.open_run(out)
    assert list(run.forks) == [slip]
    pair = run.pair(slip, PERM)
    record = json.loads(fork_at(out, slip).pair_file.read_text())
    (stored,) = record["pairs"]
    for col in PAIR_COLUMNS:
        if col == "run":
            continue
        assert _same(pair.row[col], stored[col]), (col, pair.row[col], stored[col])
    assert pair.type == stored["type"] and pair.measures["type"] == stored["type"]
    # one owner of the Eq. 3 verdict: no second, contradicting flag beside it (failed <=> the fit bar not passed)
    assert "drained_fit_ok" not in stored
    assert stored["drained_fit_verdict"] in ("holds", "failed", "inapplicable", "none")
    # one time origin per name: since loading, unless the name says clock
    drained = pair.events["drained"]
    assert drained.onset_time == pytest.approx(stored["drained_onset"])             # pair.json: since loading
    assert drained.onset_clock == pytest.approx(stored["drained_onset"] + pair.time_offset)
    assert pair.events["undrained"].end_time == pytest.approx(stored["undrained_end"])
    parent = run.slips.loc[slip]             # the drained branch retraces the parent's slip: same onset
    assert drained.onset_time == pytest.approx(parent["onset_time"], abs=1.0)
    ds = pair.series
    assert list(ds["branch"].values) == ["drained", "undrained"]
    for branch, sub in (("drained", pair.drained), ("undrained", pair.undrained)):
        v = ds["wall_vx"].sel(branch=branch)
        inside = np.isin(ds["time"].values, sub.series["time"].values)
        np.testing.assert_array_equal(v.values[inside], sub.series["wall_vx"].values)
        assert np.isnan(v.values[~inside]).all()
        assert ds["wall_vx"].attrs["units"] == "v0"
    assert ds["pressure_mean"].attrs["units"] == "E"
    assert np.isnan(ds["pressure_mean"].sel(branch="drained")).all()
    assert pair.undrained.info.permeability == pytest.approx(PERM)
    for branch in ("drained", "undrained"):
        f, curve = pair.fits[branch], pair.fit_curve(branch)
        assert (curve is None) == (f is None or not np.isfinite(f.omega))
        if curve is not None:           # A sin(omega (t - t0)) over its half period, on the time axis since loading
            assert curve.attrs["units"] == "v0" and curve.values.max() == pytest.approx(abs(f.amplitude), rel=1e-3)
            assert float(curve["time"][0]) == pytest.approx(f.t0 - pair.time_offset)
            assert float(curve["time"][-1] - curve["time"][0]) == pytest.approx(f.half_period)
    table = run.fork(slip).pairs
    assert list(table.columns) == list(PAIR_COLUMNS) and len(table) == 1


def test_snapshots_equal_the_file(forked):
    out, slip = forked
    run = gouge.open_run(out)
    assert len(run.snapshots) >= 1
    snap = run.snapshot(-1)
    with h5py.File(out / "run.h5", "r") as h5:
        name = sorted(h5["snapshots"])[-1]
        g = h5["snapshots"][name]
        for key, var in snap.data_vars.items():
            np.testing.assert_array_equal(var.values, g[key][...])
            assert var.attrs["units"] == pint_unit(g[key].attrs["unit"]) and var.attrs["description"]
        assert snap.attrs["step"] == g.attrs["step"]
        assert snap.attrs["time"] == pytest.approx(g.attrs["time"] - run.time_offset)
    wet = run.pair(slip, PERM).undrained
    assert len(wet.snapshots) >= 1
    grid = wet.snapshot(0)
    with h5py.File(wet.info.h5_path, "r") as h5:
        g = h5["snapshots"][sorted(h5["snapshots"])[0]]
        np.testing.assert_array_equal(grid["pressure"].values, g["pressure"][...])
        (x0, z0), (dx, dz) = g["pressure"].attrs["origin"], g["pressure"].attrs["spacing"]
    assert grid["pressure"].dims == ("x_cell", "z_cell") and grid["porosity"].attrs["units"] == "1"
    assert grid["x_cell"].values[0] == pytest.approx(x0 + dx / 2)
    assert grid["z_cell"].values[1] == pytest.approx(z0 + 1.5 * dz)
    np.testing.assert_allclose(np.diff(grid["x_cell"].values), dx)


def _hashes(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_opening_changes_no_byte(forked):
    out, slip = forked
    before = _hashes(out)
    run = gouge.open_run(out)
    run.series.load()
    run.slips
    [s for s in run.snapshots]
    pair = run.pair(slip, PERM)
    pair.series
    pair.undrained.snapshot(0)
    gouge.open_study(out)
    assert _hashes(out) == before


def test_open_study_equals_pair_json(forked):
    out, slip = forked
    df = gouge.open_study(out)
    record = json.loads(fork_at(out, slip).pair_file.read_text())
    assert len(df) == len(record["pairs"]) == 1
    row = df.iloc[0]
    for col in PAIR_COLUMNS:
        if col != "run":
            assert _same(row[col], record["pairs"][0][col]), col
    with h5py.File(out / "run.h5", "r") as h5:
        assert row["seed"] == h5.attrs["seed"]
    assert row["k"] == SCENE["loading"]["spring_constant"] and row["sigma"] > 0
    if slip == 1:
        assert bool(row["transient"])                        # slip 1 is always transient (analysis.study)
    assert df.groupby("permeability").size().tolist() == [1] and df["permeability"].iloc[0] == pytest.approx(PERM)


def test_wall_velocity_draws_only_fits_that_hold(forked):
    """plots.axes.wall_velocity draws a branch's Eq. 3 curve only when its verdict is "holds": the
    pair's real fits, then the same fits made to fail the bar and made inapplicable (m_eff 9 m_b)."""
    import dataclasses

    import matplotlib.pyplot as plt

    from gouge_cli.plots.axes import wall_velocity

    out, slip = forked
    pair = gouge.open_run(out).pair(slip, PERM)
    real = pair.fits
    assert real["drained"] is not None and np.isfinite(real["drained"].omega)

    def drawn(fits: dict) -> tuple[set, str]:
        pair.result = dataclasses.replace(pair.result, drained_fit=fits["drained"], undrained_fit=fits["undrained"])
        ax = wall_velocity(pair)
        names = {b for b in ("drained", "undrained") for line in ax.get_lines()
                 if str(line.get_label()).startswith(f"Eq. 3 fit, {b}")}
        text = " ".join(t.get_text() for t in ax.texts)
        plt.close(ax.figure)
        return names, text

    original = pair.result
    try:
        names, _ = drawn(real)
        assert names == {b for b, f in real.items() if f is not None and f.verdict == "holds"}
        failed = {b: f and dataclasses.replace(f, success=False, message="R^2 = 0.4 < 0.5") for b, f in real.items()}
        names, text = drawn(failed)
        assert names == set() and "Eq. 3 fit not drawn, drained: fit failed: R^2 = 0.4 < 0.5" in text
        far = {b: f and dataclasses.replace(f, success=True, half_period_ratio=3.0) for b, f in real.items()}
        names, text = drawn(far)
        assert names == set() and "Eq. 3 does not apply" in text
        near = {b: f and dataclasses.replace(f, success=True, half_period_ratio=1.1) for b, f in real.items()}
        assert drawn(near)[0] == {b for b, f in real.items() if f is not None and np.isfinite(f.omega)}
    finally:
        pair.result = original


def test_plot_helpers_return_axes(forked):
    import matplotlib.pyplot as plt

    from gouge_cli.plots.axes import series, table_scatter, wall_velocity

    out, slip = forked
    run = gouge.open_run(out)
    pair = run.pair(slip, PERM)
    ax = wall_velocity(pair)
    lines = ax.get_lines()
    fits = [b for b in ("drained", "undrained") if pair.fits[b] is not None and pair.fits[b].verdict == "holds"]
    assert len(lines) == 2 + len(fits)                     # two branches, their Eq. 3 fits that hold
    V_s = run.info.V_s
    onset = pair.events["drained"].onset_time                  # since loading, as the time axis
    np.testing.assert_allclose(lines[0].get_ydata(), pair.series["wall_vx"].sel(branch="drained").values / V_s)
    np.testing.assert_allclose(lines[0].get_xdata(), pair.series["time"].values - onset)      # since the onset
    if "drained" in fits:
        assert lines[1].get_ydata().max() == pytest.approx(abs(pair.fits["drained"].amplitude) / V_s, rel=1e-3)
    ax = series(run, ["tau_over_sigma"])
    np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), run.series["tau_over_sigma"].values)
    ax = table_scatter(gouge.open_study(out), "permeability", "stress_drop_ratio")
    assert ax.get_xscale() == "log" and ax.get_xlabel() == "permeability [d_grain^2]"
    plt.close("all")


WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from gouge_cli.config import build_config
    from gouge_cli.io.runwriter import RunFile
    w = RunFile(Path(sys.argv[1]) / "run.h5", build_config({}), 0.1, flush_rows=1000,
                extra_attrs={"n_grains": 10, "width": 5.0, "wall_mass_per_length": 2.0})
    for i in range(25):
        w.append({"time": 100.0 + i, "load_time": float(i), "wall_vx": 1e-5 * i, "tau_over_sigma": 0.1})
    w.flush()
    for i in range(25, 30):                       # buffered, not flushed
        w.append({"time": 100.0 + i, "load_time": float(i), "wall_vx": 1e-5 * i, "tau_over_sigma": 0.1})
    print("flushed", flush=True)
    time.sleep(60)
""")


def test_run_in_progress_opens(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path)], stdout=subprocess.PIPE, env=env, text=True)
    try:
        assert proc.stdout.readline().strip() == "flushed"
        run = gouge.open_run(tmp_path)
        assert run.status == "running"
        ds = run.series
        assert ds.sizes["time"] == 25                      # what was flushed
        np.testing.assert_allclose(ds["wall_vx"].values, 1e-5 * np.arange(25))
        np.testing.assert_allclose(ds["time"].values, np.arange(25.0))
        assert len(run.slips) == 0
        with pytest.raises(AnalysisError) as err:          # refused as the analysis commands refuse it
            gouge.open_run(tmp_path, allow_running=False)
        assert err.value.exit_code == EXIT_BAD_INPUT
        cli = gouge_cli("analyze", tmp_path)
        assert cli.exit_code == EXIT_BAD_INPUT
        assert " ".join(str(err.value).split())[:80] in " ".join(cli.output.split())
    finally:
        proc.kill()
        proc.wait()


def test_damaged_file_gives_the_cli_error(forked, tmp_path):
    out, _ = forked
    bad = tmp_path / "bad"
    bad.mkdir()
    data = (out / "run.h5").read_bytes()
    (bad / "run.h5").write_bytes(data[: len(data) // 3])
    with pytest.raises(NotARunError) as err:
        gouge.open_run(bad)
    assert err.value.exit_code == EXIT_BAD_INPUT
    cli = gouge_cli("analyze", bad)
    assert cli.exit_code == EXIT_BAD_INPUT
    assert " ".join(str(err.value).split())[:60] in " ".join(cli.output.split())
    with pytest.raises(NotARunError) as err:
        gouge.open_run(tmp_path / "missing")
    assert err.value.exit_code == EXIT_BAD_INPUT


def test_tutorial_runs_on_the_small_run(forked, tmp_path):
    out, slip = forked
    env = dict(os.environ, GOUGE_TUTORIAL_RUN=str(out), GOUGE_TUTORIAL_SLIP=str(slip), MPLBACKEND="Agg",
               GOUGE_TUTORIAL_FIGURES=str(tmp_path),
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    before = _hashes(out)
    result = subprocess.run([sys.executable, str(ROOT / "examples" / "tutorial_api.py")], env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Type" in result.stdout and (tmp_path / "wall_velocity.png").is_file()
    assert _hashes(out) == before


def test_launchers_return_opened_runs_and_raise_the_cli_errors(forked, tmp_path):
    from gouge_cli.errors import RunDirError

    out, _ = forked
    scene = tmp_path / "tiny.yaml"
    scene.write_text(yaml.safe_dump(SCENE))
    run = gouge.run(scene, out=tmp_path / "short", overrides={"run.duration": 500.0, "name": "short"})
    assert isinstance(run, api.Run) and run.status == "finished" and run.path == tmp_path / "short"
    assert run.config.run.duration == 500.0 and run.series.sizes["time"] >= 2
    with pytest.raises(RunDirError) as err:                     # as `gouge run` into an existing run
        gouge.run(scene, out=tmp_path / "short")
    cli = gouge_cli("run", scene, "--out", tmp_path / "short")
    assert err.value.exit_code == cli.exit_code == EXIT_BAD_INPUT
    assert " ".join(str(err.value).split())[:60] in " ".join(cli.output.split())
    with pytest.raises(RunDirError) as err:                     # as `gouge restart --slip 99`
        gouge.restart(gouge.open_run(out), slip=99, perm=[PERM])
    cli = gouge_cli("restart", out, "--slip", 99, "--perm", PERM)
    assert err.value.exit_code == cli.exit_code == EXIT_BAD_INPUT and "no checkpoint for slip 99" in str(err.value)
    assert " ".join(str(err.value).split())[:60] in " ".join(cli.output.split())


def test_docstring_examples_run(forked, tmp_path, monkeypatch):
    """The examples of the API reference (gouge_cli.api's docstrings) run as written, on a copy of the
    tiny run at runs/demo: ``run``, ``slip`` (its first fork), ``fork`` and ``pair`` are what the
    examples build. The launchers' examples (run, restart, study, open_campaign) start simulations and
    are skipped here; tests below run the launchers."""
    import doctest
    import shutil

    out, _ = forked
    shutil.copytree(out, tmp_path / "runs" / "demo")
    monkeypatch.chdir(tmp_path)
    run = gouge.open_run("runs/demo")
    slip = min(run.forks)
    globs = {"gouge": gouge, "run": run, "slip": slip, "fork": run.fork(slip), "pair": run.pair(slip)}
    finder = doctest.DocTestFinder()
    runner_ = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for name in api.__all__ for t in finder.find(getattr(api, name), f"gouge_cli.api.{name}", globs=globs)
             if t.examples]       # the public names, wherever in the api package they are defined
    assert len(tests) >= 15
    for test in tests:
        runner_.run(test)
    result = runner_.summarize(verbose=False)
    assert result.failed == 0, result
