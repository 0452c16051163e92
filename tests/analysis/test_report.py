"""gouge_cli.analysis.report (with catalog, forkpairs, io.runreader) on small synthetic run files with planted block-slider slips.

The planted series is thesis Eq. 3 exactly (loading neglected during slip): slip i starts
when tau/sigma reaches MU_S[i], v = (mu_s - mu_d) sigma / sqrt(k m) sin(omega t'),
omega = sqrt(k/m), and lasts pi/omega.
"""

from __future__ import annotations

import csv
import json
import math

import h5py
import numpy as np
import pytest
import yaml

from gouge_cli import errors as E
from gouge_cli.analysis import catalog as C
from gouge_cli.analysis import forkpairs as FP
from gouge_cli.io import runreader as RF
from gouge_cli.analysis import report as R

M, K, SIGMA, V_S, MU_D = 2.0, 0.5, 1.0, 2e-4, 0.5       # omega = 0.5, half period 2 pi
HALF_PERIOD = math.pi * math.sqrt(M / K)
DT = 0.1


def planted(mu_s_list, tau0=0.4, quiet=1500.0, dt=DT):
    """Wall series with one Eq. 3 slip per static strength in mu_s_list; returns (series, slips)."""
    omega = math.sqrt(K / M)
    x_rest = -tau0 * SIGMA / K           # wall position such that tau(0) = tau0
    events, t_last = [], 0.0
    for mu_s in mu_s_list:
        t_on = (mu_s * SIGMA / K + x_rest) / V_S
        amp = (mu_s - MU_D) * SIGMA / K
        events.append((t_on, t_on + math.pi / omega, x_rest, amp, mu_s))
        x_rest += 2.0 * amp
        t_last = t_on + math.pi / omega
    t = np.arange(0.0, t_last + quiet, dt)
    x = np.full_like(t, -tau0 * SIGMA / K)
    v = np.zeros_like(t)
    for t_on, t_end, x0, amp, _ in events:
        x[t >= t_on] = x0
        during = (t >= t_on) & (t < t_end)
        ph = omega * (t[during] - t_on)
        x[during] = x0 + amp * (1.0 - np.cos(ph))
        v[during] = amp * omega * np.sin(ph)
        x[t >= t_end] = x0 + 2.0 * amp
    tau = K * (V_S * t - x) / SIGMA
    series = {"time": t + 100.0, "load_time": t, "wall_x": x - x[0], "wall_vx": v, "tau_over_sigma": tau,
              "porosity": 0.2 + 1e-3 * np.tanh(v / 0.01)}
    return series, events


def write_run(path, series, *, status="finished", fluid=None, extra_attrs=None):
    path.mkdir(parents=True, exist_ok=True)
    config = {"name": path.name, "loading": {"spring_constant": K, "velocity": V_S, "normal_stress": SIGMA},
              "slips": {"start_factor": 10.0, "end_factor": 2.0, "min_duration": 0.0, "min_slip": 0.0,
                        "merge_gap": 0.0},
              "fluid": fluid}
    with h5py.File(path / "run.h5", "w") as h5:
        h5.attrs["config"] = yaml.safe_dump(config)
        h5.attrs["status"] = status
        h5.attrs["dt"] = 0.01
        h5.attrs["wall_mass_per_length"] = M
        h5.attrs["width"] = 20.0
        h5.attrs["n_grains"] = 100
        h5.attrs["load_start_time"] = 100.0
        for key, value in (extra_attrs or {}).items():
            h5.attrs[key] = value
        grp = h5.create_group("series")
        for name, data in series.items():
            grp.create_dataset(name, data=np.asarray(data, float))
        h5.create_group("snapshots")
    return path


PLANTED = (0.60, 0.66, 0.56)


@pytest.fixture(scope="module")
def planted_run(tmp_path_factory):
    series, events = planted(PLANTED)
    return write_run(tmp_path_factory.mktemp("runs") / "planted", series), events


def test_catalog_finds_planted_slips(planted_run):
    run, events = planted_run
    with RF.open_run(run) as reader:
        rows = C.catalog_table(reader)
    assert [r["number"] for r in rows] == [1, 2, 3]
    for row, (t_on, t_end, _, amp, mu_s) in zip(rows, events):
        assert row["static_strength"] == pytest.approx(mu_s, abs=2e-4)
        # lo = 2 V_s crossings sit asin(2 V_s / A) / omega inside the half period
        assert row["duration"] == pytest.approx(HALF_PERIOD, rel=5e-3)
        assert row["onset_clock"] - 100.0 == pytest.approx(t_on, abs=2 * DT)      # stored clock
        assert row["onset_time"] == pytest.approx(row["onset_clock"] - 100.0, abs=1e-9)   # since loading (load_start_time 100)
        assert row["slip"] == pytest.approx(2 * amp, rel=1e-3)
        assert row["stress_drop"] == pytest.approx(2 * (mu_s - MU_D), abs=2e-3)
        assert row["peak_velocity_over_Vs"] == pytest.approx(amp * 0.5 / V_S, rel=1e-3)
        assert math.isnan(row["deborah"])
    assert math.isnan(rows[0]["recurrence"])
    assert rows[1]["recurrence"] == pytest.approx(events[1][0] - events[0][0], abs=2 * DT)
    stats = C.summary_statistics(rows)
    assert stats["static_strength"]["mean"] == pytest.approx(np.mean(PLANTED), abs=2e-4)
    assert stats["static_strength"]["std"] == pytest.approx(np.std(PLANTED), abs=2e-4)
    assert stats["recurrence"]["n"] == 2


def test_fits_return_planted_half_period(planted_run):
    run, events = planted_run
    with RF.open_run(run) as reader:
        fits = C.fit_table(reader, notch=False)
    assert len(fits) == 3
    for fit, (_, _, _, amp, mu_s) in zip(fits, events):
        assert fit["success"]
        assert fit["predicted_half_period"] == pytest.approx(HALF_PERIOD, rel=1e-12)
        assert fit["half_period"] == pytest.approx(HALF_PERIOD, rel=2e-3)
        assert fit["half_period_ratio"] == pytest.approx(1.0, rel=2e-3)
        assert fit["delta_mu"] == pytest.approx(mu_s - MU_D, rel=2e-3)
        assert fit["r2"] > 0.999
        # Eq. 7: mu_d(t) = [tau - m_b a] / sigma is the planted mu_d (+ k V_s t' of loading)
        assert fit["mean_dynamic_friction"] == pytest.approx(MU_D, abs=2e-3)
        assert fit["delta_mu_eq7"] == pytest.approx(mu_s - MU_D, abs=2e-3)


def test_slip_friction_with_notch_keeps_mean(planted_run):
    run, _ = planted_run
    with RF.open_run(run) as reader:
        entry = C.read_catalog(reader)[1]
        fr = C.slip_friction(reader, entry, notch=True)
    assert fr.drained and fr.t.shape == fr.friction.shape == fr.v_wall.shape
    assert fr.mean_mu_d == pytest.approx(MU_D, abs=5e-3)
    assert fr.mu_s == pytest.approx(PLANTED[1], abs=2e-4)


def _fork(run, slip, branch, mu_s, status="finished", fluid=None):
    series, _ = planted([mu_s], quiet=300.0)
    attrs = {"branch": branch, "fork_slip": slip, "parent_run": str(run), "parent_checkpoint": "x"}
    return write_run(run / "forks" / f"slip_{slip:03d}" / branch, series, status=status, fluid=fluid,
                     extra_attrs=attrs)


@pytest.fixture
def run_with_forks(tmp_path):
    series, _ = planted(PLANTED)
    run = write_run(tmp_path / "wet_campaign", series)
    _fork(run, 1, "drained", 0.60)
    _fork(run, 1, "perm_1e-05", 0.64, fluid={"permeability": 1e-5})    # stronger: Type II
    _fork(run, 1, "perm_0.0001", 0.57, fluid={"permeability": 1e-4})   # weaker: Type I
    return run


def test_pair_types_from_planted_strengths(run_with_forks):
    pairs, skipped = FP.run_pairs(run_with_forks)
    assert skipped == []
    by_branch = {p.branch: p.row for p in pairs}
    assert by_branch["perm_1e-05"]["type"] == "II"
    assert by_branch["perm_0.0001"]["type"] == "I"
    assert by_branch["perm_1e-05"]["strength_difference"] == pytest.approx(0.04, abs=1e-3)
    assert by_branch["perm_0.0001"]["strength_difference"] == pytest.approx(-0.03, abs=1e-3)
    assert by_branch["perm_1e-05"]["permeability"] == 1e-5
    # stronger packing, bigger drop: the Eq. 3 velocity scales with mu_s - mu_d
    assert by_branch["perm_1e-05"]["peak_velocity_ratio"] == pytest.approx(0.14 / 0.10, rel=1e-2)
    # two permeabilities: two separate summaries, never one pooled over both
    summary = FP.campaign(pairs)
    assert summary.n == 2 and [g.permeability for g in summary.groups] == [1e-5, 1e-4][::-1] \
        or [g.permeability for g in summary.groups] == [1e-5, 1e-4]
    by_perm = {g.permeability: g.pairs for g in summary.groups}
    assert set(by_perm) == {1e-5, 1e-4} and all(g.n == 1 for g in by_perm.values())
    assert (by_perm[1e-5].n_type_II, by_perm[1e-5].n_type_I) == (1, 0)
    assert (by_perm[1e-4].n_type_I, by_perm[1e-4].n_type_II) == (1, 0)
    assert by_perm[1e-5].ratios["peak_velocity_ratio"].mean == pytest.approx(0.14 / 0.10, rel=1e-2)


def test_analyze_and_write(run_with_forks):
    analysis = R.analyze_run(run_with_forks, notch=False)
    written = R.write_analysis(analysis)
    with open(written["pairs"]) as fh:
        rows = list(csv.DictReader(fh))
    assert [r["type"] for r in rows] == ["II", "I"]           # sorted by permeability
    assert list(rows[0].keys()) == list(FP.PAIR_COLUMNS)
    with open(written["catalog"]) as fh:
        assert len(list(csv.DictReader(fh))) == 3
    with h5py.File(run_with_forks / "run.h5", "r") as h5:
        assert h5["analysis/catalog/static_strength"].shape == (3,)
        assert h5["analysis/pairs/type"].asstr()[...].tolist() == ["II", "I"]
        groups = json.loads(h5["analysis"].attrs["summary"])["campaign"]["per_permeability"]
        assert [g["n_type_II"] for g in groups] == [1, 0]      # 1e-5 (Type II), then 1e-4 (Type I)
    R.write_analysis(analysis)          # a second write replaces /analysis
    summary = json.loads(written["summary"].read_text())
    assert summary["fit_summary"]["half_period"]["mean"] == pytest.approx(HALF_PERIOD, rel=2e-3)


def test_running_fork_is_a_clear_error(run_with_forks):
    _fork(run_with_forks, 2, "drained", 0.60)
    _fork(run_with_forks, 2, "perm_1e-05", 0.62, status="running")
    with pytest.raises(E.RunStillRunningError, match="status 'running'"):
        FP.classify_fork(run_with_forks / "forks" / "slip_002")
    pairs, skipped = FP.run_pairs(run_with_forks)
    assert len(pairs) == 2 and len(skipped) == 1 and "slip 2" in skipped[0]
    with pytest.raises(E.RunStillRunningError):
        FP.run_pairs(run_with_forks, strict=True)


def test_no_slip_run_and_not_a_run(tmp_path):
    t = np.arange(0.0, 500.0, 1.0)
    quiet = {"time": t, "wall_x": V_S * t, "wall_vx": np.full_like(t, V_S),
             "tau_over_sigma": 0.1 + 0 * t, "porosity": 0.2 + 0 * t}
    run = write_run(tmp_path / "quiet", quiet)
    with pytest.raises(E.NoSlipsError, match="has no slips"):
        R.analyze_run(run)
    with pytest.raises(E.NotARunError, match="not a gouge run directory"):
        R.analyze_run(tmp_path)
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "run.h5").write_text("not hdf5")
    with pytest.raises(E.NotARunError, match="cannot be read as HDF5"):
        R.analyze_run(tmp_path / "junk")
    with pytest.raises(E.RunStillRunningError):
        R.analyze_run(write_run(tmp_path / "busy", quiet, status="running"))
    with RF.open_run(run) as reader:
        with pytest.raises(E.SlipNotFoundError, match="no slip number 4"):
            C.find_slip(C.read_catalog(reader), 4)


def test_series_envelope_keeps_extremes(planted_run):
    run, _ = planted_run
    with RF.open_run(run) as reader:
        env = C.series_envelope(reader, ["wall_vx", "tau_over_sigma"], max_points=2000, chunk=7001)
        full = reader.series(["wall_vx", "tau_over_sigma"])
        n = reader.info.n_samples
    assert n > 20000 and env["time"].size <= 2002
    assert env["wall_vx"].max() == full["wall_vx"].max()
    assert env["tau_over_sigma"].min() == full["tau_over_sigma"].min()
    assert np.all(np.diff(env["time"]) >= 0)
