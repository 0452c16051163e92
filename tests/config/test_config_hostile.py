"""Hostile configs and command lines: every one is exit 2 naming the full dotted key (or the
file and line), with a short message, before anything is written (issue 17)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import MAX_LINES, MAX_MESSAGE

runner = CliRunner()
SMALL = {"packing": {"n_grains": 300, "width": 15}}


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def refused(result, *words):
    """Exit 2, every word in the message, a bounded message and no traceback."""
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and result.exception is None or isinstance(result.exception, SystemExit)
    lines = result.output.splitlines()
    assert len(lines) <= MAX_LINES + 2 and all(len(line) <= MAX_MESSAGE + 80 for line in lines), result.output[:500]
    for w in words:
        assert w in result.output, (w, result.output)


def config_and_run(path: Path, tmp_path: Path, *words, sets=()):
    """`gouge config` and `gouge run` both refuse; run writes nothing."""
    extra = [a for s in sets for a in ("--set", s)]
    refused(gouge("config", path, *extra), *words)
    out = tmp_path / "never"
    refused(gouge("run", path, "--out", out, *extra), *words)
    assert not out.exists()


def write(tmp_path: Path, data, name="c.yaml") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("key,value", [
    ("run.duration", ".inf"), ("output.series_interval", ".inf"), ("output.snapshot_interval", ".inf"),
    ("output.checkpoint_interval", ".inf"), ("slips.lead", ".inf"), ("packing.width", ".inf"),
    ("material.youngs_modulus", ".inf"), ("material.density", ".inf"), ("loading.wall_mass", ".inf"),
    ("fluid.permeability", ".inf"), ("fluid.viscosity", ".inf"), ("run.duration", ".nan"),
    ("run.duration", "'1e999 s'"), ("loading.normal_stress", "-.inf"),
])
def test_non_finite_numbers_refused(tmp_path, key, value):
    section, field = key.split(".")
    path = write(tmp_path, f"{section}:\n  {field}: {value}\n")
    config_and_run(path, tmp_path, key, "finite")


@pytest.mark.parametrize("key", ["material.friction", "loading.velocity", "packing.n_grains", "seed",
                                 "numerics.dt_safety", "scales.length_m"])
def test_booleans_are_not_numbers(tmp_path, key):
    config_and_run(write(tmp_path, SMALL), tmp_path, key, sets=[f"{key}=true"])


@pytest.mark.parametrize("sets,words", [
    (["loading.velocity=0"], ["loading.velocity", "greater than 0"]),
    (["compaction.min_time=600", "compaction.max_time=500"], ["compaction", "min_time (600) must be <= max_time"]),
    (["packing.n_grains=40", "packing.width=100"], ["packing.n_grains = 40", "packing.width"]),
    (["numerics.dt=5"], ["numerics.dt = 5", "stability bound"]),
    (["loading.wall_mass=1e-12"], ["loading.wall_mass = 1e-12", "too light"]),
    (["material.damping=10", "numerics.dt_safety=0.3"], ["material.damping = 10", "unstable"]),
    (["numerics.dt=1e-12", "packing.n_grains=2000", "packing.width=null"], ["numerics.dt", "too small to finish"]),
    (["name=.."], ["name", "plain name"]),
    (["name=."], ["name", "plain name"]),
    (["name=a/b"], ["name"]),
    (["scales.length_m=-1"], ["scales.length_m"]),
    (["scales.stress_pa=abc"], ["scales.stress_pa"]),
    (["=1"], ["'=1'", "dotted name"]),
    (["loading..velocity=1"], ["loading..velocity", "dotted name"]),
    (["material=3", "material.friction=1"], ["material", "not a section"]),
])
def test_cross_field_and_key_errors_named_by_config_and_run(tmp_path, sets, words):
    config_and_run(write(tmp_path, SMALL), tmp_path, *words, sets=sets)


@pytest.mark.parametrize("text", ["", "null\n", "false\n", "0\n", "[]\n", "''\n", "# only a comment\n"])
def test_empty_or_non_mapping_file_refused(tmp_path, text):
    config_and_run(write(tmp_path, text), tmp_path, "c.yaml")


@pytest.mark.parametrize("text,key", [
    ("packing:\n  n_grains: 300\n  n_grains: 400\n", "n_grains"),
    ("packing:\n  n_grains: 300\npacking:\n  width: 15\n", "packing"),
    ("name: a\nname: b\n", "name"),
])
def test_duplicate_keys_refused(tmp_path, text, key):
    config_and_run(write(tmp_path, text), tmp_path, "duplicate key", repr(key))


def test_non_utf8_refused(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_bytes(b"name: caf\xe9\n")
    config_and_run(path, tmp_path, "not UTF-8")


def test_deep_nesting_refused_briefly(tmp_path):
    config_and_run(write(tmp_path, "a: " + "[" * 1000 + "]" * 1000 + "\n"), tmp_path, "nested more than")
    config_and_run(write(tmp_path, "".join(" " * i + f"k{i}:\n" for i in range(1000))), tmp_path, "nested more than")


def test_alias_bomb_refused_at_once(tmp_path):
    lines = ["a: &a [x, x, x, x, x, x, x, x, x]"]
    lines += [f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]" for i in range(8)]
    path = write(tmp_path, "\n".join(lines) + "\n")
    assert len(path.read_bytes()) < 700
    start = time.perf_counter()
    config_and_run(path, tmp_path, "anchors and aliases")
    assert time.perf_counter() - start < 5.0


def test_long_values_give_short_messages(tmp_path):
    path = write(tmp_path, {"material": {"friction": "x" * 100_000}, "packing": {f"k{i}": i for i in range(500)}})
    config_and_run(path, tmp_path, "material.friction", "more characters")


def test_wrong_types_name_the_full_key(tmp_path):
    path = write(tmp_path, {"scales": {"length_m": "5e-4 m"}, "fluid": {"permeability": [1]}, "slips": "abc"})
    config_and_run(path, tmp_path, "scales.length_m")
    config_and_run(write(tmp_path, {"fluid": {"permeability": [1]}}), tmp_path, "fluid.permeability")
    config_and_run(write(tmp_path, {"slips": "abc"}), tmp_path, "slips")


def test_long_run_is_announced_with_an_estimate(tmp_path):
    result = gouge("config", write(tmp_path, SMALL), "--set", "numerics.dt=1e-6")
    assert result.exit_code == 0
    assert "this run is long" in result.output and " h at " in result.output
