"""`gouge study` end to end on a tiny scene: real runs, forks, files and figures.

Idempotence (a second invocation runs nothing), resumption (an interrupted branch is run again,
nothing else), a new --perm adds only its branches, and pair.json / pairs.csv / table.csv /
figure titles say the same thing for every pair.
"""

from __future__ import annotations

import csv
import json
import math

import h5py
import pytest
from PIL import Image
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.io.integrity import seal
from slipping import slipping_run
from factories import fork_at, scene

SCENE = scene("tiny_study", 4, numerics={"threads": 1}, run={"duration": 50000},
              output={"series_interval": 10, "snapshot_interval": 50000, "checkpoint_interval": 10000})
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def _branches(run_dir):
    return {p.parent.relative_to(run_dir / "forks").as_posix(): p.stat().st_mtime_ns
            for p in (run_dir / "forks").glob("slip_*/*/run.h5")}


@pytest.fixture(scope="module")
def study_run(tmp_path_factory):
    """A loaded tiny run and the numbers of (up to) two of its slips with checkpoints."""
    cfg, out, numbers = slipping_run(SCENE, tmp_path_factory.mktemp("runs"), slips=1)
    return cfg, out, numbers[-2:]


def test_study_end_to_end_idempotent_and_consistent(study_run):
    cfg, run_dir, slips = study_run
    arg = ",".join(map(str, slips))
    first = gouge("study", cfg, "--out", run_dir, "--perm", "1e-5", "--slips", arg, "--jobs", "2")
    assert first.exit_code == 0, first.output
    assert "loading run" in first.output and "done before" in first.output     # the run was not redone
    assert f"ran {2 * len(slips)} branches, 0 done before" in first.output
    before = _branches(run_dir)
    assert len(before) == 2 * len(slips)

    # one table row per pair, and pair.json = pairs.csv = table.csv = figure title for each
    with open(run_dir / "study" / "table.csv") as fh:
        table = {int(r["slip"]): r for r in csv.DictReader(fh)}
    with open(run_dir / "analysis" / "pairs.csv") as fh:
        pairs_csv = {int(r["slip"]): r for r in csv.DictReader(fh)}
    assert sorted(table) == sorted(pairs_csv) == slips
    for n in slips:
        pj = json.loads(fork_at(run_dir, n).pair_file.read_text())
        (p,) = pj["pairs"]
        row, trow = pairs_csv[n], table[n]
        assert p["type"] == row["type"] == trow["type"]
        assert p["main"] == row["main"] == "first"
        for key, tkey in (("drained_strength", "S_d"), ("undrained_strength", "S_u"),
                          ("peak_velocity_ratio", "peak_velocity_ratio"), ("stress_drop_ratio", "stress_drop_ratio")):
            a = p[key]
            b, c = float(row[key]) if row[key] not in ("", "nan") else None, trow[tkey]
            if a is None:
                assert b is None or math.isnan(b)
            else:
                assert a == pytest.approx(b, rel=1e-12) and a == pytest.approx(float(c), rel=1e-12)
        assert (run_dir / "study" / "figures" / f"friction_slip_{n:03d}.png").is_file()      # Eq. 7, Fig. 17
        png = Image.open(run_dir / "study" / "figures" / f"pair_slip_{n:03d}_perm_1e-05.png")
        assert p["type"] in png.text["Title"] and f"De = " in png.text["Title"]
        shaded = json.loads(png.text["Description"])
        assert shaded["type"] == p["type"]
        if p["drained_onset"] is not None:
            assert shaded["drained"][0] == pytest.approx(p["drained_onset"], rel=1e-12)
    summary = json.loads((run_dir / "study" / "summary.json").read_text())
    (group,) = summary["per_permeability"]                       # one permeability: one summary
    assert group["n_rows"] == len(slips) and group["permeability"] == 1e-5
    side = summary["side_by_side"]["1e-05"]
    assert any(line[0].startswith("Type II") and line[2] == "30 (20)" for line in side)
    _check_drained_fits(run_dir, table)
    assert any("notched" in line[0] for line in side)

    # second invocation: nothing runs, nothing is rewritten
    again = gouge("study", run_dir, "--perm", "1e-5", "--slips", arg, "--no-figures")
    assert again.exit_code == 0, again.output
    assert f"ran 0 branches, {2 * len(slips)} done before" in again.output
    assert _branches(run_dir) == before

    # an interrupted branch is run again, and only it; a new --perm adds only its branches
    victim = f"slip_{slips[0]:03d}/perm_1e-05"
    with h5py.File(run_dir / "forks" / victim / "run.h5", "a") as h5:
        h5.attrs["status"] = "interrupted"
        seal(h5)                                                # the root's checksum, as the writer keeps it
    more = gouge("study", run_dir, "--perm", "1e-5", "--perm", "1e-3", "--slips", arg, "--jobs", "2",
                 "--no-figures")
    assert more.exit_code == 0, more.output
    after = _branches(run_dir)
    changed = {k for k in after if before.get(k) != after[k]}
    assert changed == {victim} | {f"slip_{n:03d}/perm_1e-03" for n in slips}


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-12, abs=1e-15)


def _check_drained_fits(run_dir, table):
    """The table's drained fit columns are the Eq. 3 fit of that slip in the parent run, and the
    notched R^2 is 1 - SS_res / SS_tot of the refit over the slip's samples of the notched velocity
    (NaN exactly when the plain fit fails its bar or the series cannot hold the notch)."""
    import numpy as np

    from gouge_cli.analysis.catalog import NOTCH_PAD, fit_slip, fit_slip_notched, read_catalog, slip_window
    from gouge_cli.io.runreader import RunReader

    with RunReader(run_dir) as reader:
        catalog = {e.number: e for e in read_catalog(reader)}
        for n, row in table.items():
            entry = catalog[n]
            plain = fit_slip(reader, entry)
            assert _same(float(row["drained_fit_r2"]), plain.r2) and (row["drained_fit_ok"] == "True") == plain.success
            refit = fit_slip_notched(reader, entry, plain)
            notched = float(row["drained_fit_r2_notched"])
            if refit is None:
                assert math.isnan(notched), n
                continue
            assert plain.success
            _, _, j0, j1 = slip_window(reader, entry, pad=NOTCH_PAD)
            t = reader.series(["time"], j0, j1)["time"]
            idx = np.flatnonzero((t >= entry.onset_time) & (t <= entry.end_time))
            tt, vv = t[idx[0]:idx[-1] + 1], refit.notched[idx[0]:idx[-1] + 1]
            f = refit.fit
            res = vv - f.amplitude * np.sin(f.omega * (tt - f.t0))
            r2 = 1.0 - np.sum(res ** 2) / np.sum((vv - vv.mean()) ** 2)
            assert notched == pytest.approx(r2, rel=1e-9, abs=1e-12) and notched <= 1.0, (n, notched, r2)


def test_study_bad_input(study_run):
    cfg, run_dir, _ = study_run
    r = gouge("study", run_dir, "--perm", "1e-5", "--slips", "99")
    assert r.exit_code == EXIT_BAD_INPUT and "slip(s) 99" in r.output
    r = gouge("study", run_dir, "--slips", "1")
    assert r.exit_code == EXIT_BAD_INPUT and "--perm" in r.output
    r = gouge("study", run_dir, "--perm", "1e-5", "--slips", "x-y")
    assert r.exit_code == EXIT_BAD_INPUT and "--slips" in r.output
    r = gouge("study", run_dir, "--perm", "1e-5", "--main", "biggest")
    assert r.exit_code == EXIT_BAD_INPUT and "--main" in r.output
