"""Sphinx directives that write gouge's reference pages from the code, and run its tutorials.

Reference (reST, used in ``docs/reference/*.rst``):

``.. gouge-cli::``          every command, argument and option of the typer app (its click group)
``.. gouge-config::``       every config key: default, unit, allowed range, meaning (pydantic models,
                            through :func:`gouge_cli.config_doc.key_rows`)
``.. gouge-file:: NAME``    a file layout table from the module that owns the format (run, series,
                            snapshot, slip, checkpoint, analysis, rundir, pair, campaign)
``.. gouge-exit-codes::``   exit codes and error types from :mod:`gouge_cli.errors`

Tutorials (MyST, used in ``docs/tutorials/*.md``):

``{gouge-tutorial} examples/NN_name.sh``: a literate shell script. ``# %% [markdown]`` starts a text
cell (its lines lose their leading ``# ``), ``# %%`` a code cell. The script runs once (until it
changes; then every tutorial runs again, in page order) in a scratch directory they share
(:func:`tutorial_dir`), holding links to ``configs/`` and ``examples/``, with ``gouge`` as
``python -m gouge_cli.cli`` of this checkout; each code cell is shown with its output, and the
commands run are exactly those shown (the tutorials use the fast scene ``configs/tutorial.yaml``).
A text cell's ``![alt](path)`` of a file the script wrote is copied into the docs.

``{gouge-tutorial} examples/name.py``: a notebook in the percent format (the same cell markers),
run cell by cell in one Python process like a Jupyter kernel (:func:`run_notebook`): a cell's
printed output and the value of its last expression are shown, and every matplotlib figure it left
open is saved and shown below it. The page links a downloadable ``.ipynb`` of the same cells
(:func:`write_ipynb`, plain JSON in the nbformat 4 layout). ``:env: NAME=VALUE ...`` sets
environment variables for the run (shown on the page).

``GOUGE_DOCS_SKIP_TUTORIALS=1`` builds the pages without running them (a quick check of the prose).
A failing cell fails the build.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
import typing
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList
from sphinx.util.nodes import nested_parse_with_titles

ROOT = Path(__file__).resolve().parents[2]
CELL = "@@gouge-cell@@"


def _parse(directive: Directive, text: str) -> list[nodes.Node]:
    """``text`` (reST in a .rst page, MyST in a .md page) parsed in place, section titles allowed."""
    node = nodes.Element()
    nested_parse_with_titles(directive.state, StringList(text.splitlines(), source="gouge_docs"), node)
    return node.children


def _plain(text: str) -> str:
    """reST-escaped text: no emphasis, substitution or reference markup outside ``literals``."""
    out = []
    for i, piece in enumerate(re.split(r"(``[^`]+``)", text)):
        if i % 2:
            out.append(piece)
            continue
        piece = piece.replace("\\", "\\\\").replace("*", "\\*").replace("`", "\\`").replace("|", "\\|")
        out.append(re.sub(r"_(?!\w)|(?<!\w)_", r"\\_", piece))
    return "".join(out)


def _roles_to_literals(text: str) -> str:
    """Sphinx roles in a module docstring (:mod:`x`, :func:`~a.b`) as ``x`` literals."""
    return re.sub(r":\w+:`~?([^`]+)`", r"``\1``", text)


DOC_PATH = re.compile(r"\bdocs/([\w/]+)\.md\b")


def _cell(text) -> str:
    """One list-table cell (reST), on one logical line: a source path ``docs/x/y.md`` becomes a link to
    that page, and a cell that reST would read as a list ("-", the dimensionless unit) stays text."""
    text = _roles_to_literals(str(text)).replace("\n", " ").strip()
    pieces = DOC_PATH.split(text)
    out = "".join(f":doc:`/{piece}`" if i % 2 else _plain(piece) for i, piece in enumerate(pieces))
    if re.match(r"[-*+](\s|$)", out):
        out = "\\" + out
    return out or " "


def list_table(header: list[str], rows: list[list], widths: str = "auto") -> str:
    out = [".. list-table::", "   :header-rows: 1", f"   :widths: {widths}", ""]
    for row in [header, *rows]:
        out.append("   * - " + _cell(row[0]))
        out += ["     - " + _cell(c) for c in row[1:]]
    return "\n".join(out) + "\n"


def _literal(text: str) -> str:
    return "::\n\n" + textwrap.indent(textwrap.dedent(text).strip("\n"), "    ") + "\n"


# ---------------------------------------------------------------- command line

def _kind(param) -> str:
    """'int', 'float', 'path', 'text'... of a click/typer parameter (lists and Optional unwrapped)."""
    if getattr(param, "type", None) is not None:
        return param.type.name
    ann = param.type_descriptor.annotation
    args = [a for a in typing.get_args(ann) if a is not type(None)]
    ann = args[0] if args else ann
    return {"str": "text", "Path": "path"}.get(getattr(ann, "__name__", str(ann)), getattr(ann, "__name__", str(ann)))


class CliDirective(Directive):
    def run(self):
        import typer

        from gouge_cli.cli.main import app

        group = typer.main.get_command(app)          # a click group (typer may vendor click)
        Context = group.context_class
        ctx = Context(group, info_name="gouge")
        parts = [f"``gouge`` -- {_cell(group.help or '')}", "",
                 list_table(["option", "meaning"], [[", ".join(p.opts), p.help or ""]
                                                  for p in group.params if p.param_type_name == "option"]
                            + [["-h, --help", "show a command's help and exit"]])]
        for name in sorted(group.list_commands(ctx)):
            cmd = group.get_command(ctx, name)
            usage = " ".join(cmd.collect_usage_pieces(Context(cmd, info_name=name, parent=ctx)))
            parts += [f".. _cli-{name}:", "", f"gouge {name}", "-" * (len(name) + 6), "",
                      _literal(f"gouge {name} {usage}"), _cell(cmd.help or ""), ""]
            rows = []
            for p in cmd.params:
                if p.param_type_name == "argument":
                    rows.append([(p.metavar or p.name).upper(), "argument" + ("" if p.required else ", optional"),
                                 getattr(p, "help", "") or ""])
                elif p.param_type_name == "option" and "--help" not in p.opts:
                    flag = " / ".join(", ".join(o) for o in (p.opts, p.secondary_opts) if o)
                    default = p.default
                    if p.required:
                        dflt = "required"
                    elif default in (None, (), []) or p.is_flag and default is False and not p.secondary_opts:
                        dflt = ""
                    else:
                        dflt = f"default {default}"
                    kind = "flag" if p.is_flag else _kind(p)
                    rows.append([flag, ", ".join(b for b in (kind, dflt, "repeatable" if p.multiple else "") if b),
                                 p.help or ""])
            if rows:
                parts.append(list_table(["argument / option", "kind", "meaning"], rows, "25 20 55"))
        return _parse(self, "\n".join(parts))


# ---------------------------------------------------------------- config keys

class ConfigDirective(Directive):
    def run(self):
        from gouge_cli.config_doc import key_rows

        parts = []
        section = None
        for row in sorted(key_rows(), key=lambda r: r["section"] != ""):
            if row["section"] != section:
                if section is not None or parts:
                    parts.append(list_table(["key", "default", "unit", "range", "meaning"], rows, "22 12 8 14 44"))
                section = row["section"]
                title = section or "top level"
                parts += [f".. _config-{section or 'top'}:", "", f"``{title}``" if section else title,
                          "~" * (len(title) + (4 if section else 0)), "", _cell(row["section_doc"]), ""]
                rows = []
            rows.append([f"``{row['key']}``", f"``{row['default']}``", row["unit"], row["range"], row["meaning"]])
        parts.append(list_table(["key", "default", "unit", "range", "meaning"], rows, "22 12 8 14 44"))
        return _parse(self, "\n".join(parts))


# ---------------------------------------------------------------- file layouts

def _unit_table(table: dict, what: str = "name") -> str:
    """The table's units as the files write them (pint_unit: d_grain, sigma_n, '1')."""
    from gouge_cli.units import pint_unit

    return list_table([what, "unit", "meaning"], [[k, pint_unit(u), d] for k, (u, d) in table.items()], "25 12 63")


def file_layout(name: str) -> str:
    from gouge_cli.io import filedoc, rundir, runfile
    from gouge_cli.units import pint_unit

    if name == "run":
        return _literal(runfile.__doc__.split("Layout of ``run.h5``::", 1)[1].split("\n\n\n")[0]) + "\n" + \
            "Root attributes:\n\n" + _unit_table(filedoc.RUN_ATTRS, "attribute")
    if name == "series":
        return _unit_table(runfile.SERIES, "series")
    if name == "snapshot":
        return ("Datasets:\n\n" + _unit_table(filedoc.SNAPSHOT, "dataset") + "\nAttributes:\n\n"
                + _unit_table(filedoc.SNAPSHOT_ATTRS, "attribute") + "\nPressure and porosity grids:\n\n"
                + _unit_table(filedoc.GRID_ATTRS, "attribute"))
    if name == "slip":
        return _unit_table(filedoc.SLIP_ATTRS, "attribute") + "\n" + _unit_table(filedoc.SLIP_DATASETS, "dataset")
    if name == "checkpoint":
        return ("Datasets:\n\n" + _unit_table(filedoc.CHECKPOINT, "dataset") + "\nAttributes:\n\n"
                + _unit_table(filedoc.CHECKPOINT_ATTRS, "attribute"))
    if name == "analysis":
        return (_unit_table(filedoc.ANALYSIS_ATTRS, "attribute") + "\nColumn units of the catalog and fits tables "
                "(the pairs table's are listed with the pair file):\n\n"
                + list_table(["column", "unit"], [[k, pint_unit(u)] for k, u in filedoc.ANALYSIS_UNITS.items()], "40 60"))
    if name == "rundir":
        return (_roles_to_literals(textwrap.dedent(rundir.__doc__)) + "\n\nWritten by a run (what ``--force`` may remove): "
                + ", ".join(f"``{o}``" for o in rundir.OWNED) + "; lock file ``" + rundir.LOCK_NAME + "``.\n")
    if name == "pair":
        from gouge_cli.analysis.forkpairs import PAIR_COLUMNS, PAIR_TABLE
        from gouge_cli.workflows import pairs

        doc = textwrap.dedent(pairs.write_pair_json.__doc__.split("\n", 1)[1])
        return (_literal(doc.split("Raises")[0]) + "\nColumns of each entry of ``pairs`` (and of ``pairs.csv``): "
                + ", ".join(f"``{c}``" for c in PAIR_COLUMNS) + ".\n\n"
                + list_table(["column", "unit", "description"], [[c.name, c.unit, c.doc] for c in PAIR_TABLE],
                             "25 10 65"))
    if name == "study":
        from dataclasses import fields

        from gouge_cli.analysis.study import STUDY_COLUMNS, StudyRow

        return ("Columns of ``table.csv`` (one row per pair, ``StudyRow``): "
                + ", ".join(f"``{c}``" for c in STUDY_COLUMNS) + ".\n\n"
                + list_table(["column", "unit", "description"],
                             [[f.name, f.metadata["unit"], f.metadata["doc"]] for f in fields(StudyRow)], "25 10 65"))
    if name == "campaign":
        from gouge_cli.analysis import campaign_table as ct

        return (_roles_to_literals(textwrap.dedent(ct.__doc__.split("\n", 1)[1])) + "\n\nRun rows add the slip statistics "
                + ", ".join(f"``{c}``" for c in ct.RUN_STATS) + " (mean and std); pair rows hold the pair columns "
                "(:ref:`ref-pair`). ``phase_diagram.csv`` columns: "
                + ", ".join(f"``{c}``" for c in ct.PHASE_COLUMNS) + ".\n")
    if name == "campaign-results":
        from gouge_cli.workflows import campaign_results as cr

        return (_roles_to_literals(textwrap.dedent(cr.__doc__.split("\n", 1)[1])) + "\n\nFields of each record "
                "(``PieceRecord``; the JSON adds ``digest`` and ``schema``)::\n\n"
                + textwrap.indent(textwrap.dedent(cr.PieceRecord.__doc__.split("\n", 1)[1]).strip("\n"), "    ") + "\n")
    raise ValueError(f"gouge-file: unknown layout {name!r}")


class FileDirective(Directive):
    required_arguments = 1

    def run(self):
        return _parse(self, file_layout(self.arguments[0]))


# ---------------------------------------------------------------- exit codes

class ExitCodesDirective(Directive):
    def run(self):
        from gouge_cli import errors

        doc = textwrap.dedent(errors.__doc__.split("\n", 1)[1])
        codes, rest = doc.strip().split("\n\n", 1)
        rows = []
        for line in codes.splitlines():
            m = re.match(r"\s*(\d+)\s+(.*)", line)
            if m:
                rows.append([m.group(1), m.group(2)])
            else:
                rows[-1][1] += " " + line.strip()
        types = [[f"``{n}``", next((c for c in (2, 3) if issubclass(cls, (errors.InputError, errors.PhysicsFailure)[c - 2])),
                                   "-"), (cls.__doc__ or "").strip()]
                 for n, cls in vars(errors).items()
                 if isinstance(cls, type) and issubclass(cls, Exception) and cls.__module__ == errors.__name__]
        text = (list_table(["code", "meaning"], rows, "10 90") + "\n" + _cell(rest) + "\n\n"
                + list_table(["error type", "exit code", "meaning"], types, "25 10 65"))
        return _parse(self, text)


# ---------------------------------------------------------------- tutorials

def split_cells(source: str) -> list[tuple[str, str]]:
    """[(kind, text)] of a literate script: kind 'markdown' or 'code'; the shebang is dropped."""
    cells, kind, lines = [], None, []
    for line in source.splitlines():
        if line.startswith("#!"):
            continue
        m = re.match(r"# %%( \[markdown\])?\s*$", line)
        if m:
            if kind:
                cells.append((kind, "\n".join(lines).strip("\n")))
            kind, lines = ("markdown" if m.group(1) else "code"), []
            continue
        if kind == "markdown":
            line = re.sub(r"^# ?", "", line)
        lines.append(line)
    if kind:
        cells.append((kind, "\n".join(lines).strip("\n")))
    return [c for c in cells if c[1].strip()]


def _links(workdir: Path):
    workdir.mkdir(parents=True, exist_ok=True)
    for name in ("configs", "examples"):
        link = workdir / name
        if not link.exists():
            link.symlink_to(ROOT / name)


def _env(extra: dict | None = None) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
                MPLBACKEND="Agg", COLUMNS="100", TERM="dumb", **(extra or {}))


def run_tutorial(script: Path, workdir: Path, timeout: float = 1800) -> list[str]:
    """Run the code cells of ``script`` in ``workdir``; returns each code cell's output.
    Raises RuntimeError (with the output so far) when a cell fails."""
    cells = [text for kind, text in split_cells(script.read_text()) if kind == "code"]
    _links(workdir)
    preamble = textwrap.dedent(f"""\
        set -euo pipefail
        export PATH="{Path(sys.executable).parent}:$PATH"
        gouge() {{ "{sys.executable}" -m gouge_cli.cli "$@"; }}
        """)
    body = "".join(f"echo '{CELL}'\n{c}\n" for c in cells)
    proc = subprocess.run(["bash", "-c", preamble + body], cwd=workdir, env=_env(), capture_output=True, text=True,
                          timeout=timeout)
    outs = proc.stdout.split(CELL + "\n")[1:]
    if proc.returncode != 0:
        raise RuntimeError(f"{script.name}: cell {len(outs)} failed (exit {proc.returncode}):\n"
                           f"{cells[len(outs) - 1] if outs else ''}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")
    return [o.rstrip("\n") for o in outs]


NOTEBOOK_DRIVER = r"""
import ast, json, sys
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

cells, figdir, mark, fig_mark = json.loads(Path(sys.argv[1]).read_text()), Path(sys.argv[2]), sys.argv[3], sys.argv[4]
namespace = {"__name__": "__main__"}
for i, code in enumerate(cells, 1):
    print(mark, flush=True)
    tree = ast.parse(code)
    last = ast.Expression(tree.body.pop().value) if tree.body and isinstance(tree.body[-1], ast.Expr) else None
    exec(compile(tree, f"<cell {i}>", "exec"), namespace)
    if last is not None:
        value = eval(compile(last, f"<cell {i}>", "eval"), namespace)
        if value is not None and not type(value).__module__.startswith("matplotlib"):
            print(repr(value))
    for k, number in enumerate(plt.get_fignums(), 1):
        figdir.mkdir(parents=True, exist_ok=True)
        name = f"cell{i}_{k}.png"
        plt.figure(number).savefig(figdir / name, dpi=100, bbox_inches="tight")
        print(fig_mark + name)
    plt.close("all")
    sys.stdout.flush()
"""
FIGURE = "@@gouge-figure@@"


def run_notebook(script: Path, workdir: Path, figdir: Path, env: dict | None = None,
                 timeout: float = 1800) -> list[tuple[str, list[str]]]:
    """Run the code cells of a percent-format Python script in one process, as a notebook kernel
    would, in ``workdir``; returns (output, figure file names in ``figdir``) per code cell: the
    printed text, the repr of a cell's last expression (unless None or a matplotlib object), and
    every figure the cell left open. Raises RuntimeError (with the output so far) when a cell fails."""
    cells = [text for kind, text in split_cells(script.read_text()) if kind == "code"]
    _links(workdir)
    shutil.rmtree(figdir, ignore_errors=True)
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "cells.json"
        spec.write_text(json.dumps(cells))
        proc = subprocess.run([sys.executable, "-c", NOTEBOOK_DRIVER, str(spec), str(figdir), CELL, FIGURE],
                              cwd=workdir, env=_env(env), capture_output=True, text=True, timeout=timeout)
    outs = proc.stdout.split(CELL + "\n")[1:]
    if proc.returncode != 0:
        raise RuntimeError(f"{script.name}: cell {len(outs)} failed (exit {proc.returncode}):\n"
                           f"{cells[len(outs) - 1] if outs else ''}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")
    result = []
    for out in outs:
        lines = out.rstrip("\n").splitlines()
        figs = [line[len(FIGURE):] for line in lines if line.startswith(FIGURE)]
        result.append(("\n".join(line for line in lines if not line.startswith(FIGURE)), figs))
    return result


def write_ipynb(script: Path, target: Path) -> Path:
    """The cells of a percent-format script as a Jupyter notebook (nbformat 4 JSON, no outputs)."""
    def lines(text):
        out = text.splitlines(keepends=True)
        return out[:-1] + [out[-1].rstrip("\n")] if out else []

    cells = [{"cell_type": kind, "metadata": {}, "source": lines(text)} if kind == "markdown" else
             {"cell_type": "code", "execution_count": None, "metadata": {}, "outputs": [], "source": lines(text)}
             for kind, text in split_cells(script.read_text())]
    notebook = {"nbformat": 4, "nbformat_minor": 4, "cells": cells,
                "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
                             "language_info": {"name": "python"}}}
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(notebook, indent=1, ensure_ascii=False) + "\n")
    return target


def tutorial_dir(outdir) -> Path:
    """The scratch directory the tutorials share (in order: a later one may use an earlier one's
    runs): ``tutorial_runs/`` beside the HTML output."""
    return Path(outdir).resolve().parent / "tutorial_runs"


def _shorten(text: str, limit: int = 60) -> str:
    lines = text.splitlines()
    if len(lines) <= limit:
        return text
    return "\n".join(lines[: limit // 2] + [f"... ({len(lines) - limit} lines left out) ..."] + lines[-limit // 2:])


class TutorialDirective(Directive):
    required_arguments = 1
    option_spec = {"env": directives.unchanged}

    def run(self):
        env = self.state.document.settings.env
        script = ROOT / self.arguments[0]
        env.note_dependency(str(script))
        work = tutorial_dir(env.app.outdir)
        gen = Path(env.srcdir) / "_generated" / script.stem
        skip = os.environ.get("GOUGE_DOCS_SKIP_TUTORIALS") == "1"
        notebook = script.suffix == ".py"
        extra = dict(item.split("=", 1) for item in (self.options.get("env") or "").split())
        n_code = sum(kind == "code" for kind, _ in split_cells(script.read_text()))
        if skip:
            outputs = [("", [])] * n_code
        else:
            try:
                if notebook:
                    outputs = run_notebook(script, work, gen, extra)
                else:
                    outputs = [(o, []) for o in run_tutorial(script, work)]
            except (RuntimeError, subprocess.TimeoutExpired) as err:
                raise self.error(str(err)) from None
        how = "the cells run in order in one Python process" if notebook else "the commands run as shown"
        where = f" with {', '.join(f'`{k}={v}`' for k, v in extra.items())}" if extra else ""
        note = (f"This page is `{self.arguments[0]}`, run when the docs were built ({how}, in a scratch "
                f"directory holding `configs/` and `examples/`{where}); the outputs below are that run's.")
        if skip:
            note = (f"This page is `{self.arguments[0]}`; this build did not run it "
                    "(GOUGE_DOCS_SKIP_TUTORIALS=1), so it shows no outputs.")
        if notebook:
            ipynb = write_ipynb(script, gen / f"{script.stem}.ipynb")
            note += (f" Download it as a notebook: {{download}}`{ipynb.name} </_generated/{script.stem}/{ipynb.name}>` "
                     "(or open the `.py` file itself in Jupyter with the jupytext plugin).")
        note = f":::{{note}}\n{note}\n:::\n"
        parts, i = [], 0
        for kind, text in split_cells(script.read_text()):
            if note and (kind == "code" or parts):
                parts.append(note)
                note = None
            if kind == "markdown":
                def image(m):
                    if skip:
                        return f"*(figure `{m.group(2)}`, written when the tutorial runs)*"
                    src = work / m.group(2)
                    if not src.is_file():
                        raise RuntimeError(f"{script.name}: image {m.group(2)} was not written by the tutorial")
                    gen.mkdir(parents=True, exist_ok=True)
                    dst = gen / src.name
                    shutil.copyfile(src, dst)
                    return f"![{m.group(1)}](/_generated/{script.stem}/{src.name})"
                parts.append(re.sub(r"!\[([^\]]*)\]\(([^)]+)\)", image, text) + "\n")
            else:
                output, figs = outputs[i]
                parts.append(f"```{'python' if notebook else 'bash'}\n{text}\n```\n")
                if output.strip():
                    parts.append(f"```text\n{_shorten(output)}\n```\n")
                parts += [f"![figure of cell {i + 1}](/_generated/{script.stem}/{f})\n" for f in figs]
                i += 1
        return _parse(self, "\n".join(parts))


def _tutorials_together(app, env, docnames):
    """If any tutorial page is to be read, read them all, in order, from an empty scratch directory
    (a later tutorial may use an earlier one's runs)."""
    pages = sorted(d for d in env.found_docs if d.startswith("tutorials/") and d != "tutorials/index")
    if not any(d in docnames for d in pages):
        return
    shutil.rmtree(tutorial_dir(app.outdir), ignore_errors=True)
    docnames[:] = sorted(set(docnames) | set(pages))


def setup(app):
    app.connect("env-before-read-docs", _tutorials_together)
    app.add_directive("gouge-cli", CliDirective)
    app.add_directive("gouge-config", ConfigDirective)
    app.add_directive("gouge-file", FileDirective)
    app.add_directive("gouge-exit-codes", ExitCodesDirective)
    app.add_directive("gouge-tutorial", TutorialDirective)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
