"""`gouge analyze` and `gouge plot` through the CLI on a tiny real run with one fork."""

from __future__ import annotations

import csv
import json

import h5py
import matplotlib.image as mpimg
import pytest
from typer.testing import CliRunner

from gouge_cli.analysis.catalog import CATALOG_COLUMNS, FIT_COLUMNS
from gouge_cli.analysis.forkpairs import PAIR_COLUMNS
from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.plots import DPI, FIGSIZE
from gouge_cli.plots.snapshot import snapshot_pixels
from factories import fork_at

runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def forked(tiny_run, tmp_path_factory):
    """The tiny scene (2 or more slips with checkpoints), its second such slip forked with one
    undrained branch writing snapshots: (run directory, slip number)."""
    _, out, numbers = tiny_run.copy(tmp_path_factory.mktemp("analyze"))
    result = gouge("restart", out, "--slip", numbers[1], "--perm", 1e-3, "--set", "output.snapshot_interval=500",
                   "--quiet")
    assert result.exit_code == 0, result.output
    return out, numbers[1]


@pytest.fixture(scope="module")
def forked_run(forked):
    return forked[0]


def _rows(path):
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return reader.fieldnames, list(reader)


def test_analyze_writes_tables(forked):
    forked_run, slip = forked
    result = gouge("analyze", forked_run)
    assert result.exit_code == 0, result.output
    assert "block-slider fits" in result.output and "drained / undrained pairs" in result.output
    with h5py.File(forked_run / "run.h5", "r") as h5:
        n_slips = len(h5["slips"])
        assert h5["analysis/catalog/number"].shape == (n_slips,)
        assert h5["analysis/catalog/onset_time"].attrs["unit"] == "t0"
        undescribed = []
        h5.visititems(lambda name, obj: undescribed.append(name)
                      if isinstance(obj, h5py.Dataset) and "unit" not in obj.attrs else None)
        assert not undescribed, undescribed[:5]                  # every dataset has its unit, /analysis too
    assert n_slips >= 2
    header, rows = _rows(forked_run / "analysis" / "catalog.csv")
    assert header == list(CATALOG_COLUMNS) and len(rows) == n_slips
    assert [int(r["number"]) for r in rows] == list(range(1, n_slips + 1))
    assert all(float(r["duration"]) > 0 and float(r["peak_velocity_over_Vs"]) >= 10 for r in rows)
    header, rows = _rows(forked_run / "analysis" / "fits.csv")
    assert header == list(FIT_COLUMNS) and len(rows) == n_slips
    assert all(float(r["predicted_half_period"]) > 0 for r in rows)
    header, rows = _rows(forked_run / "analysis" / "pairs.csv")
    assert header == list(PAIR_COLUMNS) and len(rows) == 1
    assert rows[0]["branch"] == "perm_1e-03" and int(rows[0]["slip"]) == slip
    _check_pair_rule(fork_at(forked_run, slip).root, rows[0])


def _check_pair_rule(fork, row):
    """The pair's type follows the rule from the branches' own series: static strength S = the
    largest tau/sigma up to the compared event's onset sample (the first at or after its onset
    time, which is interpolated between samples), Type I if S_u < S_d - tol, II if
    S_u > S_d + tol, else tie; '-C' exactly when a complexity criterion fired."""
    import math

    import numpy as np

    from gouge_cli.analysis.pairs import PairDefinition
    from gouge_cli.io.runreader import RunReader

    def strength(branch, onset):
        """onset: since loading began, as in pairs.csv; the series carries the stored clock."""
        with RunReader(fork / branch) as r:
            s = r.series(["time", "tau_over_sigma"])
            origin = r.time_offset()
        onset_sample = int(np.searchsorted(s["time"], onset + origin, side="left"))
        return float(np.nanmax(s["tau_over_sigma"][:onset_sample + 1]))

    if row["type"] == "none":
        assert math.isnan(float(row["drained_onset"])) or math.isnan(float(row["undrained_onset"]))
        return
    s_d, s_u = strength("drained", float(row["drained_onset"])), strength(row["branch"], float(row["undrained_onset"]))
    assert (float(row["drained_strength"]), float(row["undrained_strength"])) == (s_d, s_u)
    tol = PairDefinition().strength_tol
    base = "I" if s_u < s_d - tol else "II" if s_u > s_d + tol else "tie"
    fired = [c for c in row["criteria"].split(",") if c]
    assert (row["base_type"], row["complex"]) == (base, str(bool(fired)))
    assert row["type"] == base + ("-C" if fired else "")


def test_analyze_json_and_bad_input(forked_run, tmp_path):
    result = gouge("analyze", forked_run, "--json", "--no-notch")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["runs"][0]["parameters"]["notch"] is False
    assert data["campaign"]["n"] == 1 and len(data["campaign"]["per_permeability"]) == 1
    result = gouge("analyze", tmp_path)
    assert result.exit_code == EXIT_BAD_INPUT and "not a gouge run directory" in result.output


def _check_png(path, size_in):
    assert path.is_file() and path.stat().st_size > 10_000, path
    image = mpimg.imread(path)
    assert image.shape[:2] == (round(size_in[1] * DPI), round(size_in[0] * DPI)), path
    assert image[..., :3].std() > 0.05, f"{path} looks blank"


def test_plot_run_and_slip(forked, tmp_path):
    forked_run, slip = forked
    result = gouge("plot", forked_run)
    assert result.exit_code == 0, result.output
    figures = forked_run / "figures"
    _check_png(figures / "overview.png", FIGSIZE["overview"])
    snaps = sorted(figures.glob("snapshot_*.png"))
    assert len(snaps) == 1

    out = tmp_path / "figs"
    result = gouge("plot", forked_run, "--slip", slip, "--out", out)
    assert result.exit_code == 0, result.output
    names = {p.name for p in out.glob("*.png")}
    expected = {"overview.png"} | {f"slip_{slip:03d}{part}.png" for part in
                                   ("", "_friction", "_pair_perm_1e-03", "_snapshot_perm_1e-03")}
    assert expected <= names, names
    _check_png(out / f"slip_{slip:03d}.png", FIGSIZE["slip"])
    _check_png(out / f"slip_{slip:03d}_friction.png", FIGSIZE["friction"])
    _check_png(out / f"slip_{slip:03d}_pair_perm_1e-03.png", FIGSIZE["pair"])
    # the undrained snapshot has a pressure field: colorbar makes it wider than the dry one
    wet = mpimg.imread(out / f"slip_{slip:03d}_snapshot_perm_1e-03.png")
    dry = mpimg.imread(snaps[0])
    sizes = set()
    with h5py.File(forked_run / f"forks/slip_{slip:03d}/perm_1e-03/run.h5", "r") as h5:
        width = float(h5.attrs["width"])
        for grp in h5["snapshots"].values():
            assert "pressure" in grp
            snap = {k: grp[k][...] for k in ("x", "z", "radius", "pressure")}
            sizes.add(snapshot_pixels(width, snap))
    assert (wet.shape[1], wet.shape[0]) in sizes
    assert wet.shape[1] > dry.shape[1]


def test_plot_missing_slip_is_bad_input(forked_run):
    result = gouge("plot", forked_run, "--slip", 99)
    assert result.exit_code == EXIT_BAD_INPUT
    assert "no slip number 99" in result.output


def _at_80_columns(*args) -> str:
    """A command's output through a pipe with COLUMNS=80 (what an 80-column terminal gets)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, COLUMNS="80", TERM="dumb")
    proc = subprocess.run([sys.executable, "-m", "gouge_cli.cli", *map(str, args)], capture_output=True, text=True,
                          env=env)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _table_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line[:1] in "┏┃┡│└╇┗"]


def test_tables_are_readable_at_80_columns(forked_run):
    """`gouge slips` and `gouge analyze` at 80 columns: no value cut (no ellipsis), no table line past the
    edge, every column header whole and every slip's row in each split table; --wide keeps one table."""
    from gouge_cli.cli.analysis_cmds import _CATALOG, _FITS, _PAIRS, _fmt

    catalog = json.loads(gouge("slips", forked_run, "--json").output)
    text = _at_80_columns("slips", forked_run)
    lines = _table_lines(text)
    assert lines and "…" not in text and max(map(len, lines)) <= 80, text
    for header in ("#", "onset [t0]", "duration [µs]", "τs/σ", "Δτ/σ", "Δτ [MPa]", "v_peak/V_s", "slip [d]",
                   "checkpoint"):
        assert header in text, header
    parts = text.count("slips (")
    assert parts >= 2                                    # 12 columns do not fit 80: split
    first_cells = [line.split("│")[1].strip() for line in lines if line.startswith("│")]
    for e in catalog:
        assert f" {_fmt(e['static_strength'], 5)} " in text
        assert first_cells.count(str(e["number"])) == parts        # the key column in every part
    wide = _at_80_columns("slips", forked_run, "--wide")
    assert "(1/" not in wide and max(map(len, _table_lines(wide))) > 80 and "…" not in wide

    text = _at_80_columns("analyze", forked_run)
    lines = _table_lines(text)
    assert "…" not in text and max(map(len, lines)) <= 80, text
    for _, header in _CATALOG[:-2] + _FITS + _PAIRS:
        assert header in text, header


def test_split_tables_fit_any_width():
    """The table helper of analyze, slips and study splits any number of columns to the width asked."""
    from rich.console import Console

    from gouge_cli.cli.analysis_cmds import _table

    columns = [("key", "#")] + [(f"c{i}", f"column number {i} [unit]") for i in range(12)]
    rows = [dict(key=n, **{f"c{i}": 12345.678 * n + i / 7 for i in range(12)}) for n in range(1, 4)]
    for width in (60, 80, 100, 140):
        console = Console(width=width, record=True, file=open("/dev/null", "w"))
        console.print(_table("a table", columns, rows, width=width))
        text = console.export_text()
        assert "…" not in text and max(map(len, text.splitlines())) <= width
        assert all(h in text for _, h in columns)
