"""Config discovery: commented defaults, JSON Schema (checked with the jsonschema package against
every shipped config), --version / -h, and the suggestion for a config path that is not there."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli import __version__
from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from gouge_cli.config import Config, FluidConfig, build_config
from gouge_cli.config_doc import commented_defaults, json_schema, split_description

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def test_commented_defaults_are_the_defaults_with_units():
    text = commented_defaults()
    assert yaml.safe_load(text) == {k: v for k, v in Config().to_dict().items() if k != "fluid"}
    assert build_config(yaml.safe_load(text)) == Config()
    lines = {line.split(":")[0].strip(): line for line in text.splitlines() if "#" in line and ":" in line}
    assert "[E]" in lines["normal_stress"] and "> 0, <= 0.1" in lines["normal_stress"] and "MPa" in lines["normal_stress"]
    assert "[t0]" in lines["duration"] and "[v0]" in lines["velocity"]
    # the fluid section is there, commented out; uncommented it gives the fluid defaults
    fluid = "\n".join(line[2:] for line in text.splitlines() if line.startswith("# fluid:") or line.startswith("#   "))
    section = yaml.safe_load(fluid)["fluid"]
    assert FluidConfig.model_validate(section) == FluidConfig()
    assert "[d^2]" in text.split("permeability:")[1].splitlines()[0]


def test_every_field_has_a_description_and_numbers_a_unit():
    def walk(model):
        for name, field in model.model_fields.items():
            sub = getattr(field.annotation, "model_fields", None)
            if sub is not None:
                walk(field.annotation)
                continue
            assert field.description, f"{model.__name__}.{name}"
            if field.annotation is float and name not in ("poisson_ratio",):
                unit, _ = split_description(field.description)
                assert unit, f"{model.__name__}.{name} has no [unit]"

    walk(Config)


def test_shipped_configs_validate_against_the_schema():
    jsonschema = pytest.importorskip("jsonschema")
    schema = json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    configs = sorted((ROOT / "configs").rglob("*.yaml"))
    assert len(configs) >= 30
    for path in configs:
        errors = [e.message for e in validator.iter_errors(yaml.safe_load(path.read_text()))]
        assert not errors, (path.name, errors)
    # and it refuses what the models refuse
    for bad in ({"loading": {"normal_stress": "24 furlongs"}}, {"loadng": {}}, {"packing": {"n_grains": 5}},
                {"fluid": {"solver": "magic"}}, {"material": {"friction": -1}}):
        assert list(validator.iter_errors(bad)), bad
    assert not list(validator.iter_errors({"loading": {"normal_stress": "24 MPa"}, "fluid": "none"}))


def test_config_command_defaults_schema_version_help(tmp_path):
    out = runner.invoke(app, ["config", "--defaults"])
    assert out.exit_code == 0 and "# fluid:" in out.output and "fluid: null" not in out.output
    target = tmp_path / "schema.json"
    out = runner.invoke(app, ["config", "--schema", str(target)])
    assert out.exit_code == 0 and json.loads(target.read_text())["title"].startswith("gouge run config")
    out = runner.invoke(app, ["--version"])
    assert out.exit_code == 0 and __version__ in out.output
    for flag in ("-h", "--help"):
        out = runner.invoke(app, [flag])
        assert out.exit_code == 0 and "export" in out.output and "movie" in out.output
    import typer

    commands = typer.main.get_command(app).commands
    for name in ("run", "restart", "resume"):
        quiet = next(p for p in commands[name].params if p.name == "quiet")
        assert quiet.help == "no progress output", name
    for name in ("restart", "movie", "bench"):
        perm = next(p for p in commands[name].params if p.name == "perm")
        assert "[d^2]" in perm.help, name
    shown = runner.invoke(app, ["restart", "-h"])                 # units survive the help rendering
    assert shown.exit_code == 0 and "kappa_c [d^2]" in shown.output and "no progress output" in shown.output


def test_missing_config_path_suggests_the_shipped_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = runner.invoke(app, ["config", "configs/demo.yaml"])
    assert out.exit_code == EXIT_BAD_INPUT
    assert str(ROOT / "configs" / "demo.yaml") in out.output and "configs/configs" not in out.output


def test_a_bracket_after_a_word_is_no_unit():
    """`pip install 'gouge[gpu]'` in a description is no unit: numerics.device has none, and every unit is
    one of the scales' (d, E, t0, ...), never a word of the text."""
    from gouge_cli.config_doc import key_rows

    assert split_description("where: cpu or gpu (pip install 'gouge[gpu]'), same bits")[0] == ""
    assert split_description("time step [t0]; default dt_safety * bound") == ("t0", "time step; default dt_safety * bound")
    rows = {r["key"]: r for r in key_rows()}
    assert rows["numerics.device"]["unit"] == ""
    assert "gouge[gpu]" in rows["numerics.device"]["meaning"]
    line = next(x for x in commented_defaults().splitlines() if x.strip().startswith("device:"))
    assert "[gpu]" not in line.split("#", 1)[1].split("gouge")[0]
    allowed = {"", "-", "t0", "d", "E", "1/t0", "m", "Pa", "kg/m3", "rho_s", "E/d", "v0", "rho d^2", "d^2", "1/E",
               "E t0"}
    assert {r["unit"] for r in rows.values()} <= allowed


def test_getting_started_lists_every_extra():
    """The extras of pyproject.toml are all named in Getting started's install section."""
    import re

    toml = (ROOT / "pyproject.toml").read_text()
    block = toml.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    extras = re.findall(r"^([\w-]+)\s*=", block, flags=re.M)
    assert "gpu" in extras and "docs" in extras
    page = (ROOT / "docs" / "getting_started.md").read_text()
    sentence = page[page.index("Extras:"):].split("\n\n")[0]
    for name in extras:
        assert re.search(rf"`{re.escape(name)}`", sentence), name
