"""The regime map's outputs from a table of pairs: regime.csv, delay.csv and their figures.

Used by `gouge campaign` (a study campaign with two permeabilities or more) and by `gouge regime
PAIRS.csv` (the same outputs again from a committed pair table, without simulating anything), which
also takes several labelled inputs (:class:`Source`: campaigns or pair tables) and draws their
groups on one set of axes (groups.csv, groups.png: e.g. layer thicknesses beside the thin layer).
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError


def read_pairs(path: str | Path) -> list[dict]:
    """The pair rows (``kind == 'pair'``) of a campaign table or of a file of pairs (a campaign
    file's: :func:`gouge_cli.workflows.campaign_tables.spec_pairs`)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file (give a campaign's table.csv, a pairs.csv or a campaign file)")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    need = {"kind", "permeability", "base_type", "peak_velocity_ratio", "stress_drop_ratio", "deborah_max"}
    missing = need - set(rows[0] if rows else need)
    if missing:
        raise InputError(f"{path}: not a pair table; missing column(s) {', '.join(sorted(missing))}")
    return [r for r in rows if r["kind"] == "pair"]


@dataclass(frozen=True)
class Source:
    """The pairs of one campaign or pair table: ``label`` names its groups and folder ('' for the
    only source: groups named by their swept values alone); ``keys``: the columns its pairs are
    never pooled over (swept keys but the seed, and the study variant; none for a pair table)."""

    label: str
    rows: list[dict]
    keys: list[str]
    table: bool = False        # a pair table: ``keys`` are candidates (:func:`table_keys`)


def table_keys(rows: list[dict]) -> list[str]:
    """The columns of a pair table that its pairs are never pooled over: the swept (dotted) config
    keys and the study variant, those that take more than one value among ``rows``."""
    candidates = [k for k in (rows[0] if rows else {}) if "." in k or k == "variant"]
    return [k for k in candidates if len({str(r.get(k)) for r in rows}) > 1]


def select_sources(sources: list[Source], where: dict[str, str]) -> list[Source]:
    """:func:`select` on each source, with the conditions on its own columns: a condition on a
    column that one source lacks leaves that source whole (e.g. ``variant=w3`` keeps a campaign
    without variants), but a column that no source has is refused. A source left without pairs
    is refused, naming it. A pair table's groups are then its :func:`table_keys` (a table.csv of
    a thickness sweep is split by thickness, never pooled; one value left by --where: one map)."""
    if len(sources) == 1:
        chosen = [(sources[0], select(sources[0].rows, where))]
    else:
        columns = [set(s.rows[0]) if s.rows else set() for s in sources]
        for key in where:
            if not any(key in c for c in columns):
                raise InputError(f"--where {key}: no input has such a column")
        chosen = [(s, select(s.rows, {k: v for k, v in where.items() if k in c})) for s, c in zip(sources, columns)]
    for s, rows in chosen:
        if not rows:
            raise InputError(f"{s.label or 'input'}: no pair rows" +
                             (" with " + ", ".join(f"{k}={v}" for k, v in where.items()) if where else ""))
    return [Source(s.label, rows, table_keys(rows) if s.table else s.keys, s.table) for s, rows in chosen]


def write_groups(pair_rows: list[dict], keys: list[str], root: Path, title: str = "") -> dict:
    """:func:`write_sources` of one source (these pairs, never pooled over ``keys``)."""
    return write_sources([Source("", pair_rows, keys)], root, title)


def _folder_name(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("_") or "source"


def write_sources(sources: list[Source], root: Path, title: str = "") -> dict:
    """:func:`write_regime` and a pairs.csv once per group: per source (under ``root/<label>/``,
    at ``root`` for an unlabelled source), per value of its ``keys`` (never pooled) under
    ``<key-value_..._hash>/`` (campaign_spec.point_name). At ``root``: summary.md
    (:func:`summary_lines` of every group), groups.csv (one row per group and permeability,
    :class:`~gouge_cli.analysis.regime.GroupCell`: the findings with seed-level intervals at the
    measured De) and, with several groups, groups.png (plots.regime.groups_figure): the thickness
    figure where the groups are thicknesses."""
    from ..analysis.campaign_table import write_table
    from ..analysis.regime import GROUP_COLUMNS, group_cells, thesis_point
    from ..plots.regime import groups_figure
    from .campaign_spec import point_name

    out = {}
    lines = []
    cells = []
    for source in sources:
        base = Path(root) / _folder_name(source.label) if source.label else Path(root)
        for values, rows in by_swept(source.rows, source.keys) if source.keys else [({}, source.rows)]:
            name = point_name(values) if values else ""
            where = ", ".join(f"{k} = {v}" for k, v in values.items())
            group = ": ".join(t for t in (source.label, where) if t) or title
            key = "/".join(t for t in (_folder_name(source.label) if source.label else "", name) if t)
            folder = base / name if name else base
            out[f"pairs[{key}]"] = write_table(rows, [], folder / "pairs.csv")
            tables = regime_tables(rows)            # (the bootstraps: once per group)
            for k, path in write_regime(rows, folder, folder, f"{title}, {group}" if title and group != title
                                        else group, tables).items():
                out[f"{k}[{key}]"] = path
            lines += summary_lines(rows, group, tables)
            cells += group_cells(group, tables[0])
    out["groups_csv"] = write_table([c.csv_row() for c in cells], [], Path(root) / "groups.csv",
                                    columns=list(GROUP_COLUMNS))
    if len({c.group for c in cells}) > 1:
        out["groups_figure"] = groups_figure(cells, thesis_point(), Path(root) / "groups.png",
                                             f"{title}: every group" if title else "")
    path = Path(root) / "summary.md"
    path.write_text("\n".join(SUMMARY_HEADER + lines) + "\n")
    out["summary"] = path
    return out


SUMMARY_HEADER = [
    "| group | coupling | kappa_c | seeds | pairs | De of the slip | Type I / II / tie | Type I by sign | -C "
    "| undrained slower | smaller drop | sign predicts type | mean strain: P / curve (median; within x3) "
    "| rate: same sign; P / predicted (median; within x3) |",
    "|" + "---|" * 14]


def _coupling(rows: list[dict]) -> str:
    """The pairs' coupling in words, from their filter_width and cell_size columns [d]."""
    def one(key):
        values = {r.get(key) for r in rows if r.get(key) not in (None, "")}
        return float(values.pop()) if len(values) == 1 else None

    w, h = one("filter_width"), one("cell_size")
    if w is None or h is None:
        return "mixed"
    return f"no filter, {h:g} d cells" if w == 0 else f"w = {w:g} d, h = {h:g} d"


def regime_tables(pair_rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """(analysis.regime.regime_rows, analysis.mechanism.mechanism_rows) of the pairs, the latter
    empty where the pairs lack the mechanism's columns: what regime.csv and mechanism.csv hold."""
    from ..analysis.mechanism import mechanism_rows
    from ..analysis.regime import regime_rows

    has_mechanism = bool(pair_rows) and "drained_dilation" in pair_rows[0]
    return regime_rows(pair_rows), mechanism_rows(pair_rows) if has_mechanism else []


def summary_lines(pair_rows: list[dict], group: str, tables: tuple | None = None) -> list[str]:
    """One markdown row per permeability of the pairs (pooled over seeds): counts, the seed-level
    95 % intervals (marked s) of the findings, and the mechanism's tests (``tables``:
    :func:`regime_tables` of the same pairs, computed here if not given)."""
    regime, mechanism = tables if tables is not None else regime_tables(pair_rows)

    def pct(row, key):
        lo, hi = float(row[f"{key}_seed_lo"]), float(row[f"{key}_seed_hi"])
        interval = f" [{100 * lo:.0f}, {100 * hi:.0f}]s" if lo == lo and hi == hi else ""
        return f"{100 * float(row[key]):.0f} %{interval}"

    mech = {m["kappa_c"]: m for m in mechanism if m["seed"] == "all"}
    coupling = _coupling(pair_rows)
    lines = []
    for r in regime:
        if r["seed"] != "all":
            continue
        m = mech.get(r["kappa_c"])
        sign = f"{m['n_predicted']}/{m['n_signed']}" if m else ""
        strain = (f"{m['collapse_ratio_median']:.0f}x; {100 * m['collapse_within_factor']:.0f} %"
                  if m and m["n_collapse"] else "")
        rate = (f"{m['rate_sign_agrees']}/{m['n_rate']}; {m['rate_ratio_median']:.2f}; "
                f"{100 * m['rate_within_factor']:.0f} %" if m and m["n_rate"] else "")
        de = (f"{r['deborah_drained_median']:.2f} ({r['deborah_drained_min']:.2f}-{r['deborah_drained_max']:.2f})"
              if r["deborah_drained_median"] == r["deborah_drained_median"] else "")
        cells = [group, coupling, f"{r['kappa_c']:g}", str(r["n_seeds"]), str(r["n_pairs"]), de,
                 f"{r['n_type_I']} / {r['n_type_II']} / {r['n_tie']}", pct(r, "type_I_sign"), pct(r, "complex"),
                 pct(r, "slower"), pct(r, "smaller_drop"), sign, strain, rate]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def select(pair_rows: list[dict], where: dict[str, float]) -> list[dict]:
    """The pair rows whose swept columns hold the given values (compared as numbers when both are)."""
    def same(a, b) -> bool:
        try:
            return float(a) == float(b)
        except (TypeError, ValueError):
            return str(a) == str(b)

    for key in where:
        if pair_rows and key not in pair_rows[0]:
            raise InputError(f"--where {key}: no such column in the pair table "
                             f"(columns: {', '.join(k for k in pair_rows[0] if '.' in k or k == 'seed')})")
    return [r for r in pair_rows if all(same(r.get(k), v) for k, v in where.items())]


def by_swept(pair_rows: list[dict], keys: list[str]) -> list[tuple[dict, list[dict]]]:
    """The pair rows split by the values of the swept keys (seed excluded: the regime map pools
    seeds), in order of appearance: a sweep over thickness or sigma is never pooled."""
    keys = [k for k in keys if k != "seed"]
    groups: dict = {}
    for r in pair_rows:
        groups.setdefault(tuple(r.get(k) for k in keys), []).append(r)
    return [(dict(zip(keys, values)), rows) for values, rows in groups.items()]


def write_regime(pair_rows: list[dict], root: Path, figs: Path, title: str = "", tables: tuple | None = None) -> dict:
    """regime.csv, delay.csv and, where the pairs carry the mechanism's columns, mechanism.csv
    under ``root``; regime_map.png, regime_delay.png, mechanism_sign.png and mechanism_collapse.png
    under ``figs``. ``tables``: :func:`regime_tables` of the same pairs (computed here if not given)."""
    from ..analysis.campaign_table import write_table
    from ..analysis.mechanism import MECHANISM_COLUMNS
    from ..analysis.regime import DELAY_COLUMNS, REGIME_COLUMNS, delay_rows, thesis_point
    from ..plots.mechanism import collapse_figure, sign_figure
    from ..plots.regime import delay_figure, regime_figure

    root, figs = Path(root), Path(figs)
    rows, mech = tables if tables is not None else regime_tables(pair_rows)
    out = {"regime_csv": write_table(rows, [], root / "regime.csv", columns=list(REGIME_COLUMNS))}
    if rows:
        out["regime_map"] = regime_figure(rows, thesis_point(), figs / "regime_map.png",
                                          f"{title}: drained/undrained findings against De" if title else "")
    delay = delay_rows(pair_rows)
    out["delay_csv"] = write_table(delay, [], root / "delay.csv", columns=list(DELAY_COLUMNS))
    if any(r["n_pairs"] for r in delay):
        out["regime_delay"] = delay_figure(pair_rows, delay, figs / "regime_delay.png",
                                           f"{title}: undrained slower, smaller drop against the onset delay"
                                           if title else "")
    if pair_rows and "drained_dilation" in pair_rows[0]:
        out["mechanism_csv"] = write_table(mech, [], root / "mechanism.csv", columns=list(MECHANISM_COLUMNS))
        if any(m["n_signed"] for m in mech):
            out["mechanism_sign"] = sign_figure(pair_rows, mech, figs / "mechanism_sign.png",
                                                f"{title}: S_u − S_d against the drained twin's dilation"
                                                if title else "")
        if any(m["n_collapse"] for m in mech):
            out["mechanism_collapse"] = collapse_figure(pair_rows, mech, figs / "mechanism_collapse.png",
                                                        f"{title}: the undrained pressure against t_D / t_w"
                                                        if title else "")
    return out
