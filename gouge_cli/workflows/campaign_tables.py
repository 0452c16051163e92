"""A campaign's tables and figures, from its results records alone: table.csv, phase_diagram.csv,
the regime map, the sweep figures and, over a normal-stress sweep, the loading cycle
(:func:`write_results`, :func:`write_recurrence`), and the rows behind them
(:func:`table_rows`, :func:`spec_pairs`)."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .campaign_results import RUN_PIECE
from .campaign_spec import CampaignSpec, load_spec
from .campaign_survey import Survey, survey
from .campaign_tasks import study_variants


def results_stale(s: Survey) -> bool:
    """Whether a piece finished after table.csv was written (or there is none yet)."""
    table = s.root / "table.csv"
    if not table.is_file():
        return bool(s.by_state("done"))
    newest = max((p.record or {}).get("finished", 0) for p in s.pieces) if s.pieces else 0
    return newest > table.stat().st_mtime


def table_rows(s: Survey) -> list[dict]:
    """The campaign table's rows, from the results records alone: per point whose run is
    recorded, its run row (``kind`` 'run': swept values, the run statistics and their
    :func:`~gouge_cli.analysis.campaign_table.reload_columns`), then one row per
    recorded pair (``kind`` 'pair': swept values, variant if the study has variants, the pair
    columns, and ``transient``), in sweep then slip order."""
    from ..analysis.campaign_table import reload_columns

    swept = s.spec.swept_keys()
    records = {(p.piece.point, p.piece.label): p.result for p in s.pieces
               if p.state == "done" and p.result is not None}
    rows = []
    for point in s.points:
        run = records.get((point.name, RUN_PIECE))
        if run is None:
            continue
        values = {k: run.result["values"].get(k) for k in swept}
        loading = point.config.loading
        rows.append({"kind": "run", "point": point.name, **values, **run.result["row"],
                     **reload_columns(run.result["row"], loading.normal_stress, loading.spring_constant,
                                      loading.velocity)})
        transient = set(run.result.get("transient", ()))
        forks = sorted((r for (name, label), r in records.items() if name == point.name and label != RUN_PIECE),
                       key=lambda r: r.result["slip"])
        for fork in forks:
            for pair in fork.result["pairs"]:
                rows.append({"kind": "pair", "point": point.name, **values, **pair,
                             "transient": int(pair["slip"]) in transient})
    return rows


def spec_pairs(spec_path: Path) -> tuple[list[dict], list[str]]:
    """(pair rows, the keys they are never pooled over: the swept keys but the seed, and the study
    variant) of a campaign, from its results records."""
    spec = load_spec(spec_path)
    rows = [r for r in table_rows(survey(spec, spec_path)) if r["kind"] == "pair"]
    for r in rows:
        r.setdefault("seed", "")
    keys = [k for k in spec.swept_keys() if k != "seed"]
    if spec.study and spec.study.variants:
        keys.append("variant")
    return rows, keys


def done_points(s: Survey) -> list[str]:
    """The points whose run is recorded (the rows of table.csv and gouge_cli.api.open_campaign)."""
    return [p.piece.point for p in s.pieces if p.piece.kind == "run" and p.state == "done" and p.result is not None]


def write_results(s: Survey, log=print) -> dict:
    """table.csv (one row per run and per pair), phase_diagram.csv and the figures, from the
    results records alone."""
    from ..analysis.campaign_table import PHASE_COLUMNS, pairs_by_permeability, phase_cells, write_table
    from ..analysis.regime import thesis_point
    from ..plots.phase import pair_histograms, phase_diagram_figure, sweep_figure
    from .campaign_spec import phase_axes

    swept = [k for k in s.spec.swept_keys()]
    rows = table_rows(s)
    out = {"table": write_table(rows, swept, s.root / "table.csv")}
    figs = s.root / "figures"
    pair_rows = [r for r in rows if r["kind"] == "pair"]
    if s.spec.action == "study":
        x, y = phase_axes(s.spec)
        for variant, vrows in _by_variant(pair_rows, s.spec):
            cells = phase_cells(vrows, x, y)
            where = f"_{variant}" if variant else ""
            out[f"phase_csv{where}"] = write_table(cells, [], s.root / f"phase_diagram{where}.csv",
                                                   columns=list(PHASE_COLUMNS))
            if cells:
                out[f"phase_diagram{where}"] = phase_diagram_figure(
                    cells, x, y, figs / f"phase_diagram{where}.png",
                    s.spec.name + (f", variant {variant}" if variant else ""), thesis_point())
            out[f"pair_histograms{where}"] = pair_histograms(pairs_by_permeability(vrows),
                                                             figs / variant if variant else figs)
            for c in cells:
                log(f"phase cell{' ' + variant if variant else ''} {x}={c['x']:g}" + (f", {y}={c['y']:g}" if y else "") +
                    f": {c['n_pairs']} pairs, complex fraction {c['frac_complex']:.3g}, Type II fraction "
                    f"{c['frac_type_II']:.3g}")
    if s.spec.action == "study" and len(s.spec.study.permeabilities) >= 2:
        out.update(_regime_outputs(pair_rows, s, figs))
    sweep_keys = [k for k in swept if k != "seed"]
    if sweep_keys:
        out["slip_statistics"] = sweep_figure([r for r in rows if r["kind"] == "run"], sweep_keys,
                                              figs / "slip_statistics.png", s.spec.name)
    out.update(write_recurrence([r for r in rows if r["kind"] == "run"], s.root, figs, s.spec.name))
    return out


def write_recurrence(run_rows: list[dict], root: Path, figs: Path, title: str = "") -> dict:
    """recurrence.csv (per normal stress: the runs that stick-slip, the mean drop, recurrence and
    recurrence / (drop sigma / (k V)) with seed-level intervals: analysis.recurrence) under
    ``root`` and figures/recurrence.png, for run rows that sweep ``loading.normal_stress``;
    nothing otherwise."""
    from ..analysis.campaign_table import write_table
    from ..analysis.recurrence import RECURRENCE_COLUMNS, SIGMA_KEY, run_cycles, sigma_cycles
    from ..plots.recurrence import recurrence_figure

    if not run_rows or SIGMA_KEY not in run_rows[0]:
        return {}
    runs = run_cycles(run_rows)
    cycles = sigma_cycles(runs)
    return {"recurrence_csv": write_table([c.csv_row() for c in cycles], [], Path(root) / "recurrence.csv",
                                          columns=RECURRENCE_COLUMNS),
            "recurrence_figure": recurrence_figure(runs, cycles, Path(figs) / "recurrence.png", title)}


def _by_variant(pair_rows: list[dict], spec: CampaignSpec) -> list[tuple[str, list[dict]]]:
    """The pair rows per study variant (never pooled); one group named '' without variants."""
    names = list(spec.study.variants) if spec.study and spec.study.variants else [None]
    return [(name or "", [r for r in pair_rows if r.get("variant") == name]) for name in names]


def _regime_outputs(pair_rows: list[dict], s: Survey, figs: Path) -> dict:
    """regime.csv, delay.csv, mechanism.csv and their figures (workflows.regime_report), for a study
    campaign with two permeabilities or more; a campaign that sweeps more than seeds, or has study
    variants, gets one set per value of those keys under regime/<key>-<value>_.../, with its
    pairs.csv (permeabilities, variants and other swept values are never pooled)."""
    from .regime_report import write_groups, write_regime

    keys = [k for k in s.spec.swept_keys() if k != "seed"] + (["variant"] if study_variants(s.spec) else [])
    if not keys:
        return write_regime(pair_rows, s.root, figs, s.spec.name)
    return write_groups(pair_rows, keys, s.root / "regime", s.spec.name)


def read_sources(args: list[str]) -> list[Source]:
    """`gouge regime`'s inputs, each ``[LABEL=]PATH``: a campaign file (its results records,
    :func:`spec_pairs`) or a pair table (:func:`gouge_cli.workflows.regime_report.read_pairs`).
    An unlabelled source is named after the campaign file's stem or the table's folder when there
    are several, '' when it is the only one; labels must differ."""
    from .regime_report import Source, read_pairs

    sources = []
    for arg in args:
        label, sep, text = arg.partition("=")
        if not sep or Path(arg).exists():
            label, text = "", arg
        path = Path(text)
        spec = path.suffix in (".yaml", ".yml") and path.is_file()
        rows, keys = spec_pairs(path) if spec else (read_pairs(path), [])
        if not label and len(args) > 1:
            label = path.stem if spec else path.resolve().parent.name
        sources.append(Source(label, rows, keys, table=not spec))
    labels = [s.label for s in sources]
    if len(set(labels)) < len(labels):
        raise InputError(f"two inputs share a label ({', '.join(labels)}): give each LABEL=PATH")
    return sources
