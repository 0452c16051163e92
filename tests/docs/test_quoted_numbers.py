"""Numbers the docs quote from the code stay the code's (issue 60): the pairs page's table of the
pair definition's thresholds equals PairDefinition's defaults, the block-slider page states the fit
bar and the Eq. 3 verdict with blockslider's constants. No run, no docs build: the Markdown is read."""

from __future__ import annotations

import re
from pathlib import Path

from gouge_cli.analysis import blockslider
from gouge_cli.analysis.pairs import PairDefinition
from gouge_cli.config import Config

ROOT = Path(__file__).resolve().parents[2]


def _table_after(text: str, heading: str) -> dict[str, list[str]]:
    """The first Markdown table after ``heading``: first cell (backticks stripped) -> the other cells."""
    lines = text.split(heading, 1)[1].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    rows = {}
    for line in lines[start + 2:end]:                  # past the header and its --- row
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows[cells[0].strip("`")] = cells[1:]
    return rows


def _shown(value) -> str:
    return "none" if value is None else value if isinstance(value, str) else f"{value:g}"


def test_pairs_page_states_the_definitions_defaults():
    table = _table_after((ROOT / "docs/physics/pairs.md").read_text(), "## The definition's thresholds")
    defaults = PairDefinition().to_dict()
    assert set(table) == set(defaults), "the pairs page's table must list every field of PairDefinition.to_dict()"
    for name, value in defaults.items():
        assert table[name][0] == _shown(value), (name, table[name][0], value)
    slips = Config().slips                 # the run's slip rule: the table quotes the config's defaults
    assert (slips.start_factor, slips.end_factor) == (defaults["start_factor"], defaults["end_factor"])


def test_block_slider_page_states_the_fit_bar_and_the_verdict():
    text = (ROOT / "docs/physics/block_slider.md").read_text()
    verdicts = _table_after(text, '## When gouge says "Eq. 3 holds"')
    assert set(verdicts) == {"failed", "inapplicable", "holds"}
    failed, inapplicable = verdicts["failed"][0], verdicts["inapplicable"][0]
    assert f"R^2 < {blockslider.FIT_MIN_R2:g} (`FIT_MIN_R2`)" in failed
    assert f"factor {blockslider.FIT_PERIOD_FACTOR:g} (`FIT_PERIOD_FACTOR`)" in failed
    eq3 = blockslider.EQ3_PERIOD_FACTOR
    assert f"factor {eq3:g} (`EQ3_PERIOD_FACTOR`)" in inapplicable
    assert f"more than {eq3 ** 2:g} m_b or less than m_b / {eq3 ** 2:g}" in inapplicable
    pairs = (ROOT / "docs/physics/pairs.md").read_text()
    assert f"R^2 < {PairDefinition().min_fit_r2:g} on the undrained slip" in text and "min_fit_r2" in pairs


def test_quoted_versions_are_not_newer_than_the_package():
    """'since 0.3' in a 0.2 package: every 'gouge X.Y(.Z)' / 'since X.Y' the docs quote is a version
    that exists (at most the package's own)."""
    import tomllib

    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    own = tuple(int(p) for p in version.split(".")[:3])
    pages = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "docs").rglob("*.rst")]
    pattern = re.compile(r"\b(?:gouge|since|version|before|after)\s+v?(\d+)\.(\d+)(?:\.(\d+))?\b"
                         r"(?![.\d]*\s*(?:%|t0|MPa|d\b))")
    found = []
    for page in pages:
        if "_build" in page.parts or "_generated" in page.parts:
            continue
        for match in pattern.finditer(page.read_text()):
            quoted = tuple(int(g or 0) for g in match.groups())
            if quoted[0] == 0 and quoted > own:
                found.append(f"{page.relative_to(ROOT)}: {match.group(0)!r} (package {version})")
    assert not found, "\n".join(found)


def test_readme_and_getting_started_fork_one_slip():
    """The README's tour and Getting started fork, plot and open the same slip of the demo (they
    forked slip 4 and opened slip 2's pair)."""
    pattern = re.compile(r"--slip (\d+)|slip=(\d+)|\.pair\((\d+)|slip_(\d{3})")
    numbers = {}
    for page in ("README.md", "docs/getting_started.md"):
        for match in pattern.finditer((ROOT / page).read_text()):
            numbers.setdefault(int(next(g for g in match.groups() if g)), []).append(f"{page}: {match.group(0)}")
    assert len(numbers) == 1, numbers
