"""Property-based fuzzing of configs and `--set` overrides (hypothesis): every generated invalid
input is exit 2 with the full dotted key named, a bounded message, no traceback, and no output
directory created. GOUGE_FUZZ_EXAMPLES sets the examples per property (default 60); with -s
each property prints tried / refused cleanly."""

from __future__ import annotations

import math
import os
import re
import tempfile
import typing
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.config import Config
from gouge_cli.errors import MAX_LINES, MAX_MESSAGE

runner = CliRunner()
EXAMPLES = int(os.environ.get("GOUGE_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
BASE = {"packing": {"n_grains": 300, "width": 15}}


def _kind(annotation) -> str:
    """'number', 'text', 'choice' or 'section' for a field annotation (Optional/Annotated unwrapped)."""
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    if typing.get_origin(annotation) is typing.Union and len(args) == 1:
        return _kind(args[0])
    if typing.get_origin(annotation) is typing.Annotated:
        return _kind(args[0])
    if typing.get_origin(annotation) is typing.Literal:
        return "choice"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "section"
    return {float: "number", int: "number", str: "text"}[annotation]


def _fields(model=Config, prefix=()) -> list[tuple[tuple, str, bool]]:
    """(dotted key parts, kind, optional) of every field of the config."""
    out = []
    for name, field in model.model_fields.items():
        kind = _kind(field.annotation)
        optional = type(None) in typing.get_args(field.annotation)
        out.append((prefix + (name,), kind, optional))
        if kind == "section":
            section = [a for a in typing.get_args(field.annotation) if a is not type(None)] or [field.annotation]
            out += _fields(section[0], prefix + (name,))
    return out


FIELDS = _fields()
NUMBER_LIKE = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*\S*\s*$")


def not_a_number_text():
    return st.text(min_size=1, max_size=300).filter(lambda s: not NUMBER_LIKE.match(s) and s.strip().lower()
                                                    not in ("none", "null", "~"))


def invalid_value(kind: str, optional: bool, key: tuple):
    """Values no field of this kind accepts."""
    structures = st.lists(st.integers(), max_size=3) | st.dictionaries(st.text(max_size=5), st.integers(), max_size=2,
                                                                       min_size=1)
    if kind == "number":
        return (st.sampled_from([True, False, math.inf, -math.inf, math.nan, "1e999 s", "1e999", "-1e999 MPa",
                                 "3 parsecs", "nan", "inf"]) | not_a_number_text() | structures)
    if kind == "text":
        return (st.sampled_from([".", "..", "...", "a/b", "/abs", "", "x" * 101, True, 3, 1.5])
                | st.text(min_size=1, max_size=40).filter(lambda s: not re.fullmatch(r"[A-Za-z0-9_.-]+", s)))
    if kind == "choice":
        return st.text(max_size=20).filter(lambda s: s not in ("implicit", "explicit")) | st.integers() | structures
    # a section given as something that is not a mapping
    return (st.integers() | st.floats(allow_nan=False) | st.lists(st.integers(), max_size=2)
            | not_a_number_text().filter(lambda s: not (key == ("fluid",) and s.strip().lower() == "none")))


@st.composite
def invalid_config(draw):
    """(raw config dict, dotted key of the invalid entry)."""
    data = yaml.safe_load(yaml.safe_dump(BASE))
    if draw(st.booleans()):
        parts, kind, optional = draw(st.sampled_from(FIELDS))
        value = draw(invalid_value(kind, optional, parts))
    else:     # an unknown key in a known section (or at the top)
        sections = [p for p, k, _ in FIELDS if k == "section"] + [()]
        section = draw(st.sampled_from(sections))
        known = {p[-1] for p, _, _ in FIELDS if p[:-1] == section}
        name = draw(st.from_regex(r"[a-z][a-z_]{0,20}", fullmatch=True).filter(lambda n: n not in known))
        parts, value = section + (name,), draw(st.integers() | st.text(max_size=10))
    node = data
    for part in parts[:-1]:
        node = node.setdefault(part, {}) if isinstance(node.get(part, {}), dict) else node
    node[parts[-1]] = value
    return data, ".".join(parts)


def check_refused(result, key: str, out: Path):
    assert result.exit_code == 2, (key, result.output[:2000])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = result.output.splitlines()
    assert len(lines) <= MAX_LINES + 2 and all(len(line) <= MAX_MESSAGE + 80 for line in lines), result.output[:500]
    assert key in result.output, (key, result.output[:1000])
    assert not out.exists()


COUNTS: dict[str, list[int]] = {}


def _count(name: str, ok: bool):
    tried_refused = COUNTS.setdefault(name, [0, 0])
    tried_refused[0] += 1
    tried_refused[1] += int(ok)


def refused_by_run(text: str, key: str, extra: list[str], label: str):
    """`gouge run` of this config text (plus extra arguments) into a fresh --out: refused (check_refused)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "c.yaml"
        path.write_text(text)
        out = Path(tmp) / "out"
        result = runner.invoke(app, ["run", str(path), "--out", str(out), "--quiet", *extra])
        try:
            check_refused(result, key, out)
        except AssertionError:
            _count(label, False)
            raise
        _count(label, True)


@FUZZ
@given(invalid_config())
def test_fuzzed_config_files_refused_by_run(case):
    data, key = case
    refused_by_run(yaml.safe_dump(data, allow_unicode=True), key, [], "config files")


@FUZZ
@given(st.sampled_from([f for f in FIELDS if f[1] == "number"]).flatmap(
    lambda f: st.tuples(st.just(".".join(f[0])),
                        st.sampled_from(["true", "false", ".inf", "-.inf", ".nan", "1e999", "'1e999 s'", "[1, 2]",
                                         "{a: 1}", "abc", "'3 parsecs'", "*x", "&a 1", "0x"]))))
def test_fuzzed_overrides_refused_by_run(case):
    key, value = case
    refused_by_run(yaml.safe_dump(BASE), key, ["--set", f"{key}={value}"], "overrides")


@FUZZ
@given(st.text(max_size=60), st.text(max_size=60))
def test_random_override_strings_never_crash(key, value):
    """Arbitrary text as `--set KEY=VALUE`: `gouge config` accepts it (exit 0) or refuses it with
    exit 2 and a bounded one-paragraph message; never a traceback."""
    result = runner.invoke(app, ["config", "--set", f"{key}={value}"])
    ok = result.exit_code in (0, 2) and (result.exception is None or isinstance(result.exception, SystemExit))
    if result.exit_code == 2:
        lines = result.output.splitlines()
        ok = ok and len(lines) <= MAX_LINES + 2 and all(len(line) <= MAX_MESSAGE + 80 for line in lines)
    _count("random override strings (refused or accepted cleanly)", ok)
    assert ok, (key, value, result.output[:500], repr(result.exception))


def test_report_fuzz_counts():
    """Runs last in this module: prints the counts (visible with -s)."""
    for name, (tried, refused) in COUNTS.items():
        print(f"\nfuzz {name}: {tried} tried, {refused} handled cleanly")
    assert all(tried == refused for tried, refused in COUNTS.values())
