"""gouge from Python: runs, slips, snapshots, pairs, studies and campaigns as xarray and pandas
objects, and the workflows (run, restart, study) launched from a notebook.

Usage::

    import gouge_cli as gouge

    run = gouge.open_run("runs/demo")  # what `make demo` wrote
    run.series                         # xarray.Dataset, lazy; time [t0 since loading], time_s [s]
    run.slips                          # pandas.DataFrame, one row per slip (catalog, Eq. 3 fit, checkpoint)
    run.snapshot(-1)                   # xarray.Dataset of grains (and pressure/porosity grids when wet)
    fork = gouge.restart(run, slip=4, perm=1e-5)   # drained + undrained branches of slip 4
    pair = run.pair(4, 1e-5)           # both branches on one time axis, with pair.json's measures
    gouge.open_study("runs/demo")      # pandas.DataFrame, one row per drained/undrained pair

Everything is read through :mod:`gouge_cli.io.runreader` (the one reader of run.h5) and computed
by the functions the CLI uses (analysis.catalog, analysis.forkpairs.classify_fork: the one pair
definition), so the numbers are those of ``gouge slips --json``, ``gouge analyze`` and pair.json.
Opening and reading never write a byte of a run (analyze, figures and the launchers write what
their commands write). A run in progress opens (its status says 'running') and shows the rows
flushed so far.

Units are the dimensionless scales of the run file (length d, written ``d_grain``; stress E,
time t0, velocity v0, density rho_s; V_s and sigma, written ``sigma_n``, the run's loading velocity
and normal stress); every variable carries ``units``, ``long_name`` and ``description``, and a
dimensionless one has ``units`` '1'. A plain pint registry refuses these names (none reads as one
of pint's own units): convert with :func:`to_si` (``run.to_si(obj)``), whose results carry SI
units, or quantify as they are with the run's registry
(``ds.pint.quantify(unit_registry=run.pint_registry())``; definitions as text:
``run.pint_definitions()``, :mod:`gouge_cli.units`). Every time is counted from the start of
loading unless its name says ``clock`` (the stored clock, which also counts the compaction).
Errors are gouge_cli.errors exceptions with the CLI's message; ``exc.exit_code`` is the CLI's code.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..analysis.catalog import read_catalog
from ..analysis.forkpairs import run_pairs
from ..analysis.study import transient_slips
from ..config import Config, build_config, load_config, parse_overrides
from ..errors import ConfigError, RunDirError
from ..io.layout import RunLayout
from ..io.runreader import RunReader
from .frames import pair_frame, to_si
from .views import Fork, Pair, Run, Snapshots

__all__ = ["Run", "Fork", "Pair", "open_run", "open_study", "open_campaign", "analyze", "figures", "run", "restart",
           "study", "to_si", "Snapshots"]

_NAN = float("nan")


def open_run(path: Path | str, allow_running: bool = True) -> Run:
    """Open a run directory (or its run.h5) read-only.

    Args:
        path: The run directory (a loading run or a fork branch) or its run.h5.
        allow_running: False refuses a run whose status is 'running', as the analysis commands do.

    Raises:
        ~gouge_cli.errors.NotARunError: ``path`` holds no run file.
        ~gouge_cli.errors.RunStillRunningError: The run is running and ``allow_running`` is False.

    Example:
        >>> import gouge_cli as gouge
        >>> gouge.open_run("runs/demo")
        <gouge Run ...: status finished, ... samples, ... snapshots>
    """
    return Run(path, allow_running)


def open_study(path: Path | str, main: str = "first") -> pd.DataFrame:
    """Every drained/undrained pair of a study (a run directory with forks) as one DataFrame.

    The columns are those of pairs.csv plus seed, k, sigma, V_s and transient (the thesis's rule).
    Forks that cannot be classified yet are listed in ``df.attrs["skipped"]``.

    Example:
        >>> pairs = gouge.open_study("runs/demo")
        >>> {"slip", "permeability", "type", "transient"} <= set(pairs.columns)
        True
    """
    parent = Run(path, allow_running=False)
    pairs, skipped = run_pairs(parent.path, main=main)
    with RunReader(parent.path) as r:
        transient = transient_slips(read_catalog(r))
    info, seed = parent.info, int(parent._attributes.get("seed", -1))
    rows = [dict(p.row, seed=seed, k=info.k, sigma=info.sigma, V_s=info.V_s,
                 transient=int(p.row["slip"]) in transient) for p in pairs]
    df = pair_frame(rows, ("seed", "k", "sigma", "V_s", "transient"))
    df.attrs["skipped"] = skipped
    return df


def open_campaign(spec_or_folder: Path | str) -> pd.DataFrame:
    """The campaign table of the finished pieces (from their results records), from a campaign
    file or its output folder.

    The rows are those of table.csv (``kind`` 'run' or 'pair', the point, its swept values, the
    run statistics or the pair columns) plus seed and permeability columns. The output folder
    holds the campaign.yaml it was run with.

    Example:
        >>> table = gouge.open_campaign("runs/sweep.yaml")  # doctest: +SKIP
        >>> table.groupby("loading.normal_stress")["stress_drop_mean"].mean()  # doctest: +SKIP
    """
    from ..workflows.campaign import backfill
    from ..workflows.campaign_survey import survey
    from ..workflows.campaign_tables import table_rows
    from ..workflows.campaign_spec import load_spec

    path = Path(spec_or_folder)
    if path.is_dir():
        spec_path = path / "campaign.yaml"
        spec = load_spec(spec_path).model_copy(update={"out": str(path.resolve().parent)})
        if spec.name != path.resolve().name:
            raise ConfigError(f"{path}: its campaign.yaml names campaign {spec.name!r}; give the campaign file")
    else:
        spec_path, spec = path, load_spec(path)
    s = survey(spec, spec_path)
    backfill(s, log=lambda m: None)        # a campaign run before results records: written from its folders
    rows = table_rows(s)
    seeds = {p.name: p.config.seed for p in s.points}
    for row in rows:
        row.setdefault("seed", seeds[row["point"]])
        row.setdefault("permeability", _NAN)
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- what the CLI writes


def _run_dir(run) -> Path:
    return run.path if isinstance(run, Run) else Path(run)


def analyze(run: Run | Path | str, notch: bool = True, main: str = "first", write: bool = True):
    """``gouge analyze`` of one run; returns its ``RunAnalysis`` (catalog, fits, pairs, summary).

    ``write`` also writes ``RUN/analysis/*.csv``, summary.json and /analysis in run.h5 (the only API
    call besides the launchers that writes into a run).

    Example:
        >>> analysis = gouge.analyze("runs/demo", write=False)
        >>> len(analysis.catalog) == len(gouge.open_run("runs/demo").slips)
        True
    """
    from ..analysis.report import analyze_run, write_analysis

    analysis = analyze_run(_run_dir(run), notch=notch, main=main)
    if write:
        write_analysis(analysis)
    return analysis


def figures(run_dir: Run | Path | str, slip: int | None = None, out_dir: Path | str | None = None,
            notch: bool = True, main: str = "first") -> list[Path]:
    """``gouge plot``: the PNG figures of a run (and of slip ``slip`` and its fork); returns the files.

    ``out_dir`` defaults to RUN/figures.

    Example:
        >>> files = gouge.figures("runs/demo", out_dir="figures")
        >>> all(f.suffix == ".png" for f in files)
        True
    """
    from ..plots import make_figures

    return make_figures(run_dir=_run_dir(run_dir), slip=slip, out_dir=out_dir, notch=notch, main=main)


# --------------------------------------------------------------------------- launching


def _overrides(overrides) -> dict:
    """{"loading.velocity": 2e-5} (as it is) or ["loading.velocity=2e-5"] (parsed as ``--set``) -> {dotted key: value}."""
    if not overrides:
        return {}
    return dict(overrides) if isinstance(overrides, dict) else parse_overrides(list(overrides))


def run(config: Config | Path | str, out: Path | str | None = None, overrides=None, force: bool = False,
        quiet: bool = True) -> Run:
    """``gouge run``: compact, then load; returns the opened run.

    Args:
        config: A Config, a YAML path or a scene name.
        out: The run directory (default runs/<name>).
        overrides: {dotted key: value}, as ``--set``.
        force: Replace what a previous run left in ``out``.
        quiet: No progress bar.

    An interrupted run (Ctrl-C) comes back with status 'interrupted'; bad input raises the CLI's
    exceptions (``exc.exit_code``).

    Example:
        >>> run = gouge.run("configs/tutorial.yaml", out="runs/first")  # doctest: +SKIP
        >>> run.status  # doctest: +SKIP
        'finished'
    """
    from ..workflows.run import default_run_dir, run_scene

    if isinstance(config, Config):
        cfg = build_config(config.to_dict(), _overrides(overrides))
    else:
        cfg = load_config(config, _overrides(overrides))
    target = Path(out) if out is not None else default_run_dir(cfg)
    result = run_scene(cfg, target, force=force, quiet=quiet)
    return open_run(result.out_dir)


def restart(run: Run | Path | str, slip: int, perm=(), overrides=None, duration: float | None = None,
            force: bool = False, main: str = "first", quiet: bool = True) -> Fork:
    """``gouge restart``: drained and undrained branches of slip ``slip``; returns the opened :class:`Fork`.

    One undrained branch per ``perm`` [d^2]; pair.json is written when ``perm`` is given.
    ``duration`` [t0] bounds each branch (default: until its first slip ends).

    The pair's type (``fork.pair(K).type``) is I, II or tie, with -C when complex
    (docs/physics/pairs.md); which one a slip gives is the simulation's to say.

    Example:
        >>> fork = gouge.restart("runs/demo", slip=4, perm=3e-6)  # doctest: +SKIP
        >>> fork.pair(3e-6).type  # doctest: +SKIP
    """
    from ..workflows.fork import ForkRequest, restart as run_restart

    run_dir = _run_dir(run)
    perms = (perm,) if isinstance(perm, (int, float)) else tuple(perm)
    try:
        run_restart(ForkRequest(run_dir, slip, perms, _overrides(overrides), duration, force=force, main=main),
                    quiet=quiet)
    except RunDirError as exc:          # the CLI's words, said in Python's
        raise RunDirError(str(exc).replace("pass --force", "pass force=True")) from None
    return Fork(RunLayout(run_dir).fork(slip).root)


def study(target: Path | str, perm, slips=None, main: str = "first", jobs: int | None = None,
          out: Path | str | None = None, overrides=None, figures: bool = False, quiet: bool = True) -> pd.DataFrame:
    """``gouge study``: drained and undrained forks of every slip; returns :func:`open_study` of the run.

    ``target`` is a run directory or a config (the loading run is run first); ``slips`` (e.g.
    [3, 4] or "3-12") replaces every non-transient slip. Writes the pair types and RUN/study.

    Example:
        >>> pairs = gouge.study("runs/first", perm=1e-5, slips="2-3")  # doctest: +SKIP
        >>> pairs.groupby("type").size()  # doctest: +SKIP
    """
    from ..workflows.study import parse_slips, run_study

    perms = [perm] if isinstance(perm, (int, float)) else list(perm)
    wanted = parse_slips(slips) if isinstance(slips, str) else (sorted(slips) if slips is not None else None)
    result = run_study(Path(target), perms, wanted, main=main, jobs=jobs,
                       out=Path(out) if out is not None else None, overrides=_overrides(overrides), quiet=quiet,
                       figures=figures)
    return open_study(result.run_dir, main)
