"""Results a user reads, on a tiny real run forked at two permeabilities: one time origin in every
output, failed fits flagged everywhere, permeabilities never pooled, the comparison figure, and
`gouge restart --perm K2` adding a branch to a fork made with --perm K1."""

from __future__ import annotations

import csv
import hashlib
import json

import h5py
import pytest
from PIL import Image
from typer.testing import CliRunner

from gouge_cli.analysis import blockslider
from gouge_cli.analysis.blockslider import BlockSliderFit
from gouge_cli.analysis.forkpairs import DRAINED_DE, UNDRAINED_DE
from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from factories import branch_at, fork_at

K1, K2 = 1e-3, 1e-2
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def two_perms(tiny_run, tmp_path_factory):
    """The tiny scene's second slip with a checkpoint (number n) forked at K1, then K2 added by a
    second `gouge restart`: (run directory, first and second restart results, the drained
    branch's SHA-256 after the first, n)."""
    _, out, numbers = tiny_run.copy(tmp_path_factory.mktemp("results"))
    n = numbers[1]
    first = gouge("restart", out, "--slip", n, "--perm", K1, "--quiet")
    assert first.exit_code == 0, first.output
    drained_hash = _sha(branch_at(out, n).run_file)
    second = gouge("restart", out, "--slip", n, "--perm", K2, "--quiet", "--json")
    return out, first, second, drained_hash, n


def test_restart_prints_one_screen(two_perms):
    """`gouge restart` prints a short result (issue 60): a line per branch, one per pair with its
    type, S_u - S_d and the onsets it compares, and where the record is; the JSON behind --json."""
    out, first, _, _, n = two_perms
    lines = first.output.strip().splitlines()
    assert 4 <= len(lines) <= 15 and "{" not in first.output, first.output
    assert lines[0].startswith(f"slip {n} forked from t = ")
    assert any(line.strip().startswith("drained ") for line in lines)
    pair = next(line for line in lines if "pair drained vs perm_1e-03" in line)
    assert "onsets" in pair or "no pair" in pair or "none" in pair
    row = json.loads(fork_at(out, n).pair_file.read_text())["pairs"][0]
    if "onsets" in pair:          # the window of the comparison: when each maximum was reached (issue 60)
        when = lines[lines.index(pair) + 1]
        assert when == (f"    S_d reached at t = {row['drained_strength_time']:,.1f}, S_u at "
                        f"{row['undrained_strength_time']:,.1f} t0 (the largest tau/sigma before each onset)")
        assert row["drained_strength_time"] <= row["drained_onset"] + 1e-9
        assert row["undrained_strength_time"] <= row["undrained_onset"] + 1e-9
    assert lines[-1].startswith("record: ") and "pair.json" in lines[-1]


def test_restart_perm_adds_a_branch(two_perms):
    out, _, second, drained_hash, n = two_perms
    assert second.exit_code == 0, second.output
    fork = fork_at(out, n).root
    assert sorted(p.name for p in fork.iterdir() if p.is_dir()) == ["drained", "perm_1e-02", "perm_1e-03"]
    assert _sha(fork / "drained" / "run.h5") == drained_hash           # the drained branch was kept
    printed = json.loads(second.output[second.output.index("{"):])
    assert set(printed["branches"]) == {"drained", "perm_1e-02"}
    assert printed["branches"]["drained"]["status"] == "finished (kept)"
    pj = json.loads((fork / "pair.json").read_text())
    assert sorted(p["branch"] for p in pj["pairs"]) == ["perm_1e-02", "perm_1e-03"]
    assert pj["run"] == "../.." and (fork / pj["run"]).resolve() == out.resolve()
    again = gouge("restart", out, "--slip", n, "--perm", K1, "--quiet")     # the same K needs --force
    assert again.exit_code == EXIT_BAD_INPUT and "perm_1e-03" in again.output and "--force" in again.output


def test_one_onset_time_everywhere(two_perms, tmp_path):
    out, _, _, _, n = two_perms
    listed = gouge("slips", out, "--json")
    assert listed.exit_code == 0
    slips = json.loads(listed.output)
    assert all("attribute_units" not in e and "peak_velocity" not in e for e in slips)
    onset = next(e for e in slips if e["number"] == n)["onset_time"]
    with h5py.File(out / "run.h5", "r") as h5:
        origin = float(h5["series/time"][0] - h5["series/load_time"][0])
        clock = float(h5[f"slips/{n:03d}"].attrs["onset_time"]) if f"slips/{n:03d}" in h5 else None
        dt_sample = float(h5["series/time"][1] - h5["series/time"][0])
    assert origin > 0 and onset > 0
    if clock is not None:
        assert onset == pytest.approx(clock - origin, abs=1e-9)
    analyzed = gouge("analyze", out, "--json", "--no-notch")
    assert analyzed.exit_code == 0, analyzed.output
    run = json.loads(analyzed.output)["runs"][0]
    assert run["time_origin"] == "loading start"
    assert next(r for r in run["catalog"] if r["number"] == n)["onset_time"] == pytest.approx(onset, abs=1e-9)
    with open(out / "analysis" / "catalog.csv") as fh:
        row = next(r for r in csv.DictReader(fh) if r["number"] == str(n))
    assert float(row["onset_time"]) == pytest.approx(onset, abs=1e-6)
    assert float(row["onset_clock"]) == pytest.approx(onset + origin, abs=1e-6)
    # the drained branch retraces the parent: its compared slip is slip n, on the same clock and origin
    with open(out / "analysis" / "pairs.csv") as fh:
        pairs = list(csv.DictReader(fh))
    assert len(pairs) == 2
    pj = json.loads(fork_at(out, n).pair_file.read_text())
    for p in pairs + pj["pairs"]:
        assert float(p["drained_onset"]) == pytest.approx(onset, abs=2 * dt_sample)
    assert gouge("plot", out, "--slip", n, "--out", tmp_path).exit_code == 0
    for p in pj["pairs"]:
        png = Image.open(tmp_path / f"slip_{n:03d}_pair_{p['branch']}.png")
        shaded = json.loads(png.text["Description"])
        assert shaded["drained"][0] == pytest.approx(p["drained_onset"], rel=1e-12)


def test_two_permeabilities_are_never_pooled(two_perms, tmp_path):
    out, _, _, _, n = two_perms
    analyzed = gouge("analyze", out, "--json", "--no-notch")
    assert analyzed.exit_code == 0, analyzed.output
    groups = json.loads(analyzed.output)["campaign"]["per_permeability"]
    assert [g["permeability"] for g in groups] == [K1, K2] and all(g["n"] == 1 for g in groups)
    text = gouge("analyze", out, "--no-notch").output
    assert "κ_c = 1e-03 d²" in text and "κ_c = 1e-02 d²" in text
    with open(out / "analysis" / "pairs.csv") as fh:
        pairs = {r["branch"]: r for r in csv.DictReader(fh)}
    for r in pairs.values():
        de = float(r["deborah_slip"]) if r["deborah_slip"] not in ("", "nan") else float(r["deborah_mean"])
        expected = ("drained-like" if de < DRAINED_DE else "undrained" if de >= UNDRAINED_DE else "partially drained")
        assert r["regime"] == expected
    result = gouge("plot", out, "--slip", n, "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert "every permeability on shared axes" in result.output                # `gouge plot` says what it drew
    png = Image.open(tmp_path / f"slip_{n:03d}_compare.png")
    described = json.loads(png.text["Description"])
    assert [b["branch"] for b in described["branches"]] == ["perm_1e-03", "perm_1e-02"]
    assert "De =" in png.text["Title"] or all(b["regime"] for b in described["branches"])
    assert (tmp_path / "pairs.png").is_file() and not (tmp_path / "campaign.png").exists()     # one run's pairs


def test_fit_verdicts():
    def fit(ratio, success=True, message=""):
        return BlockSliderFit(amplitude=1.0, omega=1.0, t0=0.0, half_period=100.0 * ratio, period=200.0 * ratio,
                              predicted_half_period=100.0, half_period_ratio=ratio, delta_mu=0.1, r2=0.9,
                              nrms=0.1, n_points=50, success=success, message=message, m_eff=ratio ** 2)
    assert fit(1.2).verdict == "holds" and fit(1.2).verdict_reason == ""
    bad = fit(6.0)
    assert bad.verdict == "inapplicable" and "m_eff = 36 m_b" in bad.verdict_reason
    assert fit(1.0, False, "R^2 = 0.2 < 0.5").verdict == "failed"
    assert "R^2 = 0.2" in fit(1.0, False, "R^2 = 0.2 < 0.5").verdict_reason


def test_failed_fit_is_flagged_in_every_output(two_perms, tmp_path, monkeypatch):
    out, _, _, _, n = two_perms
    monkeypatch.setattr(blockslider, "judge_fit", lambda *a, **k: (False, "forced failure for the test"))
    text = gouge("analyze", out, "--no-notch")
    assert text.exit_code == 0, text.output
    assert "failed" in text.output and "forced failure for the test" in text.output
    with open(out / "analysis" / "fits.csv") as fh:
        fits = list(csv.DictReader(fh))
    assert fits and all(r["verdict"] == "failed" and "forced failure" in r["reason"] for r in fits)
    with open(out / "analysis" / "pairs.csv") as fh:
        pairs = list(csv.DictReader(fh))
    # a pair whose undrained branch did not move has no fits (type and verdicts `none`, as at seed
    # offset 28 for kappa_c 1e-3); every pair with fits says they failed
    fitted = [r for r in pairs if r["type"] != "none"]
    assert fitted, pairs
    assert all(r["drained_fit_verdict"] == "failed" and "forced failure" in r["fit_reason"] for r in fitted)
    assert all(r["drained_fit_verdict"] == r["undrained_fit_verdict"] == "none" for r in pairs if r["type"] == "none")
    data = json.loads(gouge("analyze", out, "--json", "--no-notch").output)["runs"][0]
    assert all(f["verdict"] == "failed" and f["reason"] for f in data["fits"])
    assert all(p["drained_fit_verdict"] == "failed" for p in data["pairs"] if p["type"] != "none")
    assert gouge("plot", out, "--slip", n, "--out", tmp_path).exit_code == 0
    slip = Image.open(tmp_path / f"slip_{n:03d}.png")
    meta = json.loads(slip.text["Description"])
    assert meta["fit_drawn"] is False and meta["verdict"] == "failed" and "forced failure" in meta["reason"]
    pair = Image.open(tmp_path / f"slip_{n:03d}_pair_{fitted[0]['branch']}.png")
    assert "forced failure" in pair.text["Title"]


def test_export_from_another_directory_lands_in_the_run(two_perms, tmp_path, monkeypatch):
    """parent_run is relative to the branch folder: resolving it from the current directory wrote
    the export outside the run (into cwd/../../../export)."""
    out, _, _, _, n = two_perms
    with h5py.File(branch_at(out, n, 1e-3).run_file, "r") as h5:
        assert h5.attrs["parent_run"] == "../../.."
    elsewhere = tmp_path / "a" / "b" / "c"
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    result = gouge("export", out, "--fork", f"slip_{n:03d}/perm_1e-03")
    assert result.exit_code == 0, result.output
    assert (out / "export" / f"slip_{n:03d}_perm_1e-03.vtkhdf").is_file()
    assert not (tmp_path / "export").exists() and not any(elsewhere.iterdir())


def test_pair_verdict_of_a_failed_branch():
    """A fork whose branch failed is drawn as failed, with the branch's message (a KeyError before)."""
    from gouge_cli.plots.series import pair_verdict

    row = {"base_type": "failed", "type": "failed", "note": "undrained branch failed: pressure not finite",
           "strength_difference": float("nan"), "criteria": ""}
    assert pair_verdict(row) == "no pair: undrained branch failed: pressure not finite"
