"""`gouge plot`: which figures to draw for a run (and one of its slips)."""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..analysis.catalog import find_slip, read_catalog, slip_friction
from ..analysis.forkpairs import fork_branches, run_pairs
from ..errors import NoSlipsError
from ..io.layout import RunLayout, branch_perm_text
from ..io.runreader import RunReader
from ..io.slipcatalog import SlipEntry
from .campaign import campaign_figure
from .series import comparison_figure, friction_figure, overview_figure, pair_figure, slip_figure
from .snapshot import snapshot_figure


def _nearest_snapshot(reader: RunReader, t: float) -> str | None:
    names = reader.snapshot_names()
    if not names:
        return None
    times = np.array(reader.snapshot_times())
    return names[int(np.argmin(np.abs(times - t)))]


def undrained_friction_figure(u: RunReader, pair, path: Path, notch: bool, drained_mean: float | None) -> Path:
    """R/sigma = mu_d (1 - P*/sigma) (Eq. 6) over the pair's compared undrained event (thesis Fig. 18)."""
    main = pair.result.undrained_slip
    slip = int(pair.slip)
    entry = replace(SlipEntry.from_slip(main, slip), static_strength=pair.result.undrained_strength)
    fr = slip_friction(u, entry, notch=notch)
    title = (f"Slip {slip}, κ_c = {branch_perm_text(pair.branch)} d² ({pair.measured.regime}): "
             "combined resistance R/σ (Eq. 6)")
    return friction_figure(fr, u.info.V_s, path, title=title,
                           drained_mean=drained_mean)


def make_figures(run_dir: Path | str, slip: int | None = None, out_dir: Path | str | None = None,
                 notch: bool = True, main: str = "first") -> list[Path]:
    """Draw the figures of one run into ``out_dir`` (default ``RUN/figures``); returns the files.

    Always: ``overview.png`` (four panels, slips shaded) and ``snapshot_latest.png`` (the run's
    last snapshot); ``pairs.png`` when the run has two or more drained/undrained pairs (every
    forked slip of this run: one summary per permeability; `gouge campaign` draws its own). With
    ``slip=N``: ``slip_NNN.png`` (the slip magnified, Eq. 3 fit),
    ``slip_NNN_friction.png`` (mu_d(t), Eq. 7), for a fork of that slip ``slip_NNN_compare.png``
    (drained and every permeability on shared axes) and per undrained branch B:
    ``slip_NNN_pair_B.png`` (drained black, undrained blue, pore pressure),
    ``slip_NNN_friction_B.png`` (R/sigma, Eq. 6) and ``slip_NNN_snapshot_B.png`` (the branch's
    snapshot nearest its peak velocity, pressure shaded) when the branch wrote snapshots.
    Pairs are classified by :func:`~gouge_cli.analysis.forkpairs.classify_fork` (``main``: the compared
    events), so titles and shading say what pairs.csv and pair.json say.
    Raises :class:`~gouge_cli.errors.AnalysisError` subclasses for bad input.
    """
    run_dir = Path(run_dir)
    written: list[Path] = []
    with RunReader(run_dir) as reader:
        out = Path(out_dir) if out_dir is not None else reader.info.run_dir / "figures"
        catalog = read_catalog(reader)
        entry = None
        if slip is not None:
            if not catalog:
                raise NoSlipsError(f"{reader.info.describe()} has no slips, so there is no slip {slip} to plot")
            entry = find_slip(catalog, slip)
        written.append(overview_figure(reader, catalog, out / "overview.png"))
        names = reader.snapshot_names()
        if names:
            snap = reader.snapshot(names[-1])
            written.append(snapshot_figure(snap, reader.info.width, out / "snapshot_latest.png",
                                           title=f"{reader.info.run_dir}: last snapshot (step {snap['step']})",
                                           sigma=reader.info.sigma,
                                           time_offset=reader.time_offset()))
        drained_mean = None
        if entry is not None:
            tag = f"slip_{slip:03d}"
            written.append(slip_figure(reader, entry, out / f"{tag}.png"))
            fr = slip_friction(reader, entry, notch=notch)
            drained_mean = fr.mean_mu_d
            written.append(friction_figure(fr, reader.info.V_s, out / f"{tag}_friction.png",
                                           title=f"{reader.info.run_dir}, slip {slip}: "
                                                 f"{'dynamic friction μ_d(t) (Eq. 7)' if fr.drained else 'combined resistance R/σ (Eq. 6)'}"))
    pairs, _ = run_pairs(run_dir, main=main)
    if entry is not None:
        fork = RunLayout(run_dir).fork(slip).root
        drained_dir, undrained_dirs = fork_branches(fork)
        mine = [p for p in pairs if p.drained_dir.parent == fork]
        if drained_dir is not None and mine:
            with RunReader(drained_dir) as d, ExitStack() as stack:
                readers = [(stack.enter_context(RunReader(p.undrained_dir)), p) for p in mine]
                written.append(comparison_figure(d, readers, out / f"slip_{slip:03d}_compare.png"))
            with RunReader(drained_dir) as d:
                for pair in mine:
                    with RunReader(pair.undrained_dir) as u:
                        branch = pair.undrained_dir.name
                        tag = f"slip_{slip:03d}"
                        written.append(pair_figure(d, u, pair, out / f"{tag}_pair_{branch}.png"))
                        main = pair.result.undrained_slip
                        if main is not None:
                            written.append(undrained_friction_figure(
                                u, pair, out / f"{tag}_friction_{branch}.png", notch, drained_mean))
                        if u.snapshot_names():
                            if main is not None:
                                t_peak = main.peak_time
                            else:
                                s = u.series(["time", "wall_vx"])
                                t_peak = float(s["time"][int(np.argmax(s["wall_vx"]))])
                            name = _nearest_snapshot(u, t_peak)
                            snap = u.snapshot(name)
                            written.append(snapshot_figure(
                                snap, u.info.width, out / f"{tag}_snapshot_{branch}.png",
                                title=f"Slip {slip}, κ_c = {branch_perm_text(branch)} d²: grains and pore pressure "
                                      f"{snap['time'] - t_peak:+.4g} t₀ from the peak velocity",
                                sigma=u.info.sigma,
                                time_offset=u.time_offset()))
    if len(pairs) >= 2:
        written.append(campaign_figure(pairs, out / "pairs.png", title=f"{Path(run_dir).resolve()}: every pair"))
    return written


#: What each figure of `gouge plot` shows, by file-name pattern (fnmatch), for the command's listing.
FIGURES = (
    ("overview.png", "the whole run: τ/σ, v_w/V_s, porosity and wall displacement against time since "
                     "loading began, slips shaded"),
    ("snapshot_latest.png", "the grains and force chains at the run's last snapshot"),
    ("slip_???.png", "slip N magnified with its Eq. 3 fit (drawn only when the fit holds; otherwise the reason)"),
    ("slip_???_friction.png", "slip N: dynamic friction μ_d(t) of Eq. 7 with the wall velocity"),
    ("slip_???_compare.png", "slip N: the drained branch and every permeability on shared axes, De in the legend"),
    ("slip_???_pair_*.png", "slip N: drained against one permeability, with the pore pressure"),
    ("slip_???_friction_*.png", "slip N, one permeability: combined resistance R/σ of Eq. 6"),
    ("slip_???_snapshot_*.png", "slip N, one permeability: grains and pore pressure nearest the peak velocity"),
    ("pairs.png", "every pair of the run (all forked slips): pair types and undrained/drained peak-velocity "
                  "ratios, per permeability"),
)


def describe_figure(path: Path) -> str:
    """What the figure at ``path`` shows (:data:`FIGURES`), or ''."""
    import re
    from fnmatch import fnmatch

    name = Path(path).name
    text = next((text for pattern, text in FIGURES if fnmatch(name, pattern)), "")
    number = re.match(r"slip_(\d+)", name)
    return text.replace("slip N", f"slip {int(number.group(1))}") if number else text
