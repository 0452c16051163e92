"""The documentation site builds with no warning (`make docs`: sphinx -W -n), its reference pages hold
every command, option and config key, every tutorial under examples/ runs as printed (the shell ones on
configs/tutorial.yaml, the Python API notebook on their run), and the build leaves the work tree clean.

The build runs in a temporary folder, once per test session (module fixture). The tutorials run the
shipped configs with their committed seeds: a run's bits are the same on any machine and thread
count, so what they find (the demo's slips) does not depend on where the suite runs. The seed
offset of the suite (GOUGE_TEST_SEED_OFFSET) is therefore not passed to them: the tutorials are
the documentation of the shipped scenes, not a packing of the suite.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("sphinx", reason="the docs extra is not installed (pip install -e '.[docs]')")
pytest.importorskip("myst_parser", reason="the docs extra is not installed")

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
import gouge_docs  # noqa: E402

TUTORIALS = sorted((ROOT / "examples").glob("[0-9][0-9]_*.sh"))


def _text(path: Path) -> str:
    """The visible text of an HTML page."""
    html = re.sub(r"<script.*?</script>|<style.*?</style>", "", path.read_text(), flags=re.S)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html)).replace("&#8212;", "-").replace("&amp;", "&")


def _untracked() -> set[str]:
    """Files git would list as new or changed in the checkout (ignored ones left out)."""
    proc = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=ROOT, capture_output=True,
                          text=True)
    return set(proc.stdout.splitlines()) if proc.returncode == 0 else set()


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("docs")
    env = {k: v for k, v in os.environ.items() if k not in ("GOUGE_TEST_SEED_OFFSET", "GOUGE_DOCS_SKIP_TUTORIALS")}
    env["PYTHONPATH"] = str(ROOT)
    before = _untracked()
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q", "-b", "html",
                           str(ROOT / "docs"), str(out / "html")], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=3000)
    proc.new_files = _untracked() - before
    return out, proc


def test_docs_build_leaves_the_work_tree_clean(site):
    """Nothing the build or its tutorials write lands in the checkout outside ignored folders."""
    out, proc = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not proc.new_files, sorted(proc.new_files)


def test_docs_build_without_warnings(site):
    out, proc = site
    assert proc.returncode == 0, proc.stderr[-6000:]
    assert proc.stderr.strip() == "", proc.stderr[-6000:]
    for page in ("index", "getting_started", "physics/fluid", "validation", "performance/history", "developer",
                 "reference/files", "reference/exit_codes", "reference/api"):
        assert (out / "html" / f"{page}.html").is_file(), page


def test_reference_holds_every_command_option_and_key(site):
    import typer

    from gouge_cli.cli.main import app
    from gouge_cli.config_doc import key_rows

    out, proc = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    cli = _text(out / "html" / "reference" / "cli.html")
    group = typer.main.get_command(app)
    ctx = group.context_class(group, info_name="gouge")
    for name in group.list_commands(ctx):
        assert f"gouge {name}" in cli, name
        for p in group.get_command(ctx, name).params:
            if p.param_type_name == "option":
                assert p.opts[0] in cli, (name, p.opts)
    config = _text(out / "html" / "reference" / "config.html")
    for row in key_rows():
        assert row["key"] in config, row["key"]
    codes = _text(out / "html" / "reference" / "exit_codes.html")
    for code in ("0", "2", "3", "130"):
        assert re.search(rf"\b{code}\b", codes), code


def test_split_cells_reads_a_literate_script():
    cells = gouge_docs.split_cells("#!/usr/bin/env bash\n# %% [markdown]\n# # Title\n#\n# text\n# %%\necho hi\n"
                                   "# %% [markdown]\n# more\n")
    assert cells == [("markdown", "# Title\n\ntext"), ("code", "echo hi"), ("markdown", "more")]


def test_a_failing_tutorial_cell_is_an_error(tmp_path):
    script = tmp_path / "99_fails.sh"
    script.write_text("# %%\necho before\n# %%\nfalse\n# %%\necho never\n")
    with pytest.raises(RuntimeError, match="cell 2 failed"):
        gouge_docs.run_tutorial(script, tmp_path / "work")


@pytest.mark.parametrize("script", TUTORIALS, ids=lambda p: p.stem)
def test_tutorial_ran_as_printed(site, script):
    """Every code cell of the tutorial ran (the build fails otherwise) and its page shows the outputs of
    the commands it prints (no option added behind the reader's back)."""
    out, proc = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    page = _text(out / "html" / "tutorials" / f"{script.stem}.html")
    assert "run when the docs were built (the commands run as shown" in page
    assert "run.duration=60000" not in page
    work = gouge_docs.tutorial_dir(out / "html")
    first = work / "runs" / "first"
    if script.stem.startswith("01"):
        assert re.search(r"finished: runs/first \(\d+ steps", page)
        catalog = json.loads(subprocess.run([sys.executable, "-m", "gouge_cli.cli", "slips", str(first), "--json"],
                                            capture_output=True, text=True, check=True,
                                            env=dict(os.environ, PYTHONPATH=str(ROOT))).stdout)
        assert len(catalog) >= 3          # the tutorials fork slips 2 and 3
    elif script.stem.startswith("02"):
        pair = json.loads((first / "forks" / "slip_002" / "pair.json").read_text())
        assert pair["pairs"] and pair["pairs"][0]["type"] in page
    elif script.stem.startswith("03"):
        assert (first / "study" / "table.csv").is_file() and (first / "study" / "report.md").is_file()
    elif script.stem.startswith("04"):
        table = (work / "runs" / "campaigns" / "sigma_sweep" / "table.csv").read_text().splitlines()
        assert len(table) == 3            # header + one row per swept normal stress
    elif script.stem.startswith("05"):
        assert list((first / "export").glob("*.vtkhdf"))
        assert list((first / "figures").glob("slip_002_movie.*"))


def test_python_api_notebook_ran_with_its_figures(site):
    """The notebook tutorial (examples/tutorial_api.py) is a page of the tutorials list, run at every build:
    its cells' outputs and figures are on the page, and its .ipynb is downloadable."""
    out, proc = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    html = out / "html" / "tutorials" / "06_python_api.html"
    page = _text(html)
    assert "import gouge_cli as gouge" in page and "cells run in order in one Python process" in page
    pair = json.loads((gouge_docs.tutorial_dir(out / "html") / "runs" / "first" / "forks" / "slip_002"
                       / "pair.json").read_text())
    assert f"Type {pair['pairs'][0]['type']}" in page          # the Pair's repr, printed by a cell
    assert len(re.findall(r'<img [^>]*src="[^"]*cell\d+_\d+\.png"', html.read_text())) >= 3
    notebooks = list((out / "html" / "_downloads").rglob("tutorial_api.ipynb"))
    assert notebooks and json.loads(notebooks[0].read_text())["nbformat"] == 4
    index = (out / "html" / "tutorials" / "index.html").read_text()
    assert "06_python_api.html" in index


def test_write_ipynb_keeps_the_cells(tmp_path):
    script = tmp_path / "nb.py"
    script.write_text("# %% [markdown]\n# # Title\n# %%\nx = 1\nx\n")
    nb = json.loads(gouge_docs.write_ipynb(script, tmp_path / "nb.ipynb").read_text())
    assert [c["cell_type"] for c in nb["cells"]] == ["markdown", "code"]
    assert "".join(nb["cells"][1]["source"]) == "x = 1\nx"


def test_run_notebook_shows_the_last_expression_and_figures(tmp_path):
    script = tmp_path / "nb.py"
    script.write_text("# %%\nimport matplotlib.pyplot as plt\nx = 41\nx + 1\n# %%\nplt.plot([0, 1])\nprint('drawn')\n")
    outputs = gouge_docs.run_notebook(script, tmp_path / "work", tmp_path / "figs")
    assert outputs[0] == ("42", [])
    assert outputs[1][0] == "drawn" and outputs[1][1] == ["cell2_1.png"] and (tmp_path / "figs" / "cell2_1.png").is_file()


def test_key_rows_cover_every_config_key_once():
    """The config reference's rows: every leaf key of the defaults (the fluid section included), once."""
    from gouge_cli.config import Config, FluidConfig
    from gouge_cli.config_doc import key_rows

    def leaves(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from leaves(v, f"{prefix}{k}.")
            elif not (k == "fluid" and v is None):
                yield prefix + k

    expected = set(leaves(Config().to_dict())) | {f"fluid.{k}" for k in FluidConfig().model_dump(mode="json")}
    keys = [r["key"] for r in key_rows()]
    assert len(keys) == len(set(keys)) and set(keys) == expected
    assert all(r["meaning"] for r in key_rows())


def test_table_cells_keep_a_dash_and_link_doc_paths():
    """A dimensionless unit "-" stays a dash (reST would make it a bullet) and a source path docs/x.md
    becomes a link to the page."""
    assert gouge_docs._cell("-") == "\\-"
    assert gouge_docs._cell("Time step (docs/physics/timestep.md).") == "Time step (:doc:`/physics/timestep`)."
    assert gouge_docs._cell("*x* and |y|") == "\\*x\\* and \\|y\\|"


def test_config_reference_shows_units_and_links(site):
    out, proc = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    html = (out / "html" / "reference" / "config.html").read_text()
    assert "docs/physics/" not in _text(out / "html" / "reference" / "config.html")
    assert 'href="../physics/timestep.html' in html
    assert not re.search(r"<td><ul", html)          # no cell turned into a bullet list


def test_equations_render_without_a_network(site):
    """MathJax is served from the site itself (sphinx-mathjax-offline), no page loads it from a CDN, and
    the physics pages hold display equations, the numerical implementation page among them."""
    out, proc = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    html = out / "html"
    assert (html / "_static" / "mathjax" / "tex-chtml.js").is_file()
    for page in html.rglob("*.html"):
        text = page.read_text()
        assert "cdn.jsdelivr.net" not in text and "cdnjs" not in text, page
    fluid = (html / "physics" / "fluid.html").read_text()
    assert 'src="../_static/mathjax/tex-chtml.js"' in fluid
    assert fluid.count('class="math') >= 6
    assert (html / "physics" / "numerics.html").is_file()
