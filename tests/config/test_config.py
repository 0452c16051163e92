"""Config validation: unknown keys, types, ranges, SI strings, dotted overrides, dt bound."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gouge_cli.config import build_config, format_override, load_config, parse_overrides
from gouge_cli.errors import ConfigError
from gouge_cli.model.timestep import choose_dt, stability_bound


def error_of(data, overrides=None) -> str:
    with pytest.raises(ConfigError) as info:
        build_config(data, overrides)
    return str(info.value)


def test_defaults_build():
    cfg = build_config({})
    assert cfg.material.youngs_modulus == 1.0 and cfg.material.poisson_ratio == 0.2
    assert cfg.loading.normal_stress == 3e-4 and cfg.fluid is None
    with pytest.raises(Exception):
        cfg.material.friction = 0.1             # frozen


@pytest.mark.parametrize("data,key", [
    ({"materail": {}}, "materail"),
    ({"material": {"frction": 0.3}}, "material.frction"),
    ({"numerics": {"dt": 0.1, "dtt": 0.1}}, "numerics.dtt"),
    ({"fluid": {"permeabilty": 1e-5}}, "fluid.permeabilty"),
])
def test_unknown_key_refused(data, key):
    msg = error_of(data)
    assert key in msg and "unknown key" in msg


@pytest.mark.parametrize("data,key,value", [
    ({"material": {"friction": "abc"}}, "material.friction", "abc"),
    ({"packing": {"n_grains": 1.5}}, "packing.n_grains", "1.5"),
    ({"packing": {"n_grains": "many"}}, "packing.n_grains", "many"),
    ({"loading": {"normal_stress": True}}, "loading.normal_stress", "True"),
    ({"loading": {"normal_stress": [1, 2]}}, "loading.normal_stress", "[1, 2]"),
    ({"fluid": {"solver": "magic"}}, "fluid.solver", "magic"),
])
def test_wrong_type_refused(data, key, value):
    msg = error_of(data)
    assert key in msg and value in msg


@pytest.mark.parametrize("data,key,value,bound", [
    ({"material": {"friction": -1}}, "material.friction", "-1", "0"),
    ({"material": {"friction": 11}}, "material.friction", "11", "10"),
    ({"material": {"poisson_ratio": 0.5}}, "material.poisson_ratio", "0.5", "0.5"),
    ({"loading": {"normal_stress": 0.2}}, "loading.normal_stress", "0.2", "0.1"),
    ({"loading": {"normal_stress": "9 GPa"}}, "loading.normal_stress", "0.1125", "0.1"),
    ({"packing": {"n_grains": 5}}, "packing.n_grains", "5", "20"),
    ({"numerics": {"dt_safety": 1.5}}, "numerics.dt_safety", "1.5", "1"),
])
def test_out_of_range_refused(data, key, value, bound):
    msg = error_of(data)
    assert key in msg and value in msg
    assert ("greater than" in msg or "less than" in msg) and bound in msg.split(key, 1)[1]


def test_out_of_range_si_string_quotes_user_input():
    msg = error_of({"loading": {"normal_stress": "9 GPa"}})
    assert "9 GPa" in msg


def test_cross_field_check_names_values():
    msg = error_of({"packing": {"diameter_min": 1.1, "diameter_max": 0.9}})
    assert "diameter_max" in msg and "0.9" in msg and "1.1" in msg


@pytest.mark.parametrize("field,text,expected", [
    (("loading", "normal_stress"), "24 MPa", 3e-4),
    (("loading", "normal_stress"), "24e6 Pa", 3e-4),
    (("loading", "normal_stress"), "  24 MPa ", 3e-4),
    (("loading", "normal_stress"), "3e-4", 3e-4),          # a bare number in a string
    (("material", "youngs_modulus"), "80 GPa", 1.0),
    (("packing", "width"), "0.025 m", 50.0),
    (("packing", "width"), "25 mm", 50.0),
    (("loading", "velocity"), "5.7032 m/s", 5.7032 / math.sqrt(8e10 / 2460.0)),
    (("compaction", "min_time"), "1 us", 1e-6 / (5e-4 / math.sqrt(8e10 / 2460.0))),
    (("loading", "spring_constant"), "1.6e5 MPa/m", 1.6e11 / (8e10 / 5e-4)),
    (("loading", "wall_mass"), "1 kg/m", 1.0 / (2460.0 * 5e-4 ** 2)),
    (("fluid", "permeability"), "2.5e-12 m2", 1e-5),
    (("fluid", "viscosity"), "1e-3 Pa s", 1e-3 / (8e10 * 5e-4 / math.sqrt(8e10 / 2460.0))),
    (("fluid", "compressibility"), "4.5e-10 1/Pa", 36.0),
    (("fluid", "filter_width"), "1.5 mm", 3.0),            # the fluid's lengths are lengths like the others
    (("fluid", "cell_size"), "0.75 mm", 1.5),
    (("fluid", "filter_width"), 2, 2.0),                   # a plain number: [d], as in every config file
])
def test_si_strings(field, text, expected):
    section, key = field
    cfg = build_config({section: {key: text}})
    assert getattr(getattr(cfg, section), key) == pytest.approx(expected, rel=1e-12)


def test_si_strings_use_configured_scales():
    cfg = build_config({"scales": {"stress_pa": 1e10}, "loading": {"normal_stress": "24 MPa"}})
    assert cfg.loading.normal_stress == pytest.approx(2.4e-3, rel=1e-12)


@pytest.mark.parametrize("text", ["24 m/s", "24 MPaa", "24 kg"])
def test_wrong_unit_refused_naming_allowed_units(text):
    msg = error_of({"loading": {"normal_stress": text}})
    assert "loading.normal_stress" in msg and text.split()[1] in msg
    for unit in ("Pa", "kPa", "MPa", "GPa"):
        assert unit in msg


def test_unknown_unit_is_not_said_to_measure_something_else():
    """'24 psi' is a stress in a unit gouge does not read: the message says so, not 'does not measure stress'."""
    msg = error_of({"loading": {"normal_stress": "24 psi"}})
    assert "'psi' is not a unit gouge knows" in msg and "does not measure" not in msg
    assert "'m/s' does not measure stress" in error_of({"loading": {"normal_stress": "24 m/s"}})


def test_unit_on_dimensionless_field_refused():
    msg = error_of({"material": {"friction": "0.5 Pa"}})
    assert "material.friction" in msg


def test_dotted_overrides():
    cfg = build_config({"material": {"friction": 0.6}},
                       ["material.friction=0.3", "loading.normal_stress=24 MPa", "seed=7",
                        "numerics.dt = 0.05"])
    assert cfg.material.friction == 0.3
    assert cfg.loading.normal_stress == pytest.approx(3e-4)
    assert cfg.seed == 7 and cfg.numerics.dt == 0.05
    cfg = build_config({}, {"packing.n_grains": 500, "fluid.permeability": 1e-4})
    assert cfg.packing.n_grains == 500 and cfg.fluid.permeability == 1e-4
    # an override into a section given as 'none' turns it on
    cfg = build_config({"fluid": "none"}, ["fluid.permeability=1e-3"])
    assert cfg.fluid is not None and cfg.fluid.permeability == 1e-3
    # overrides are validated like the file
    assert "material.frction" in error_of({}, ["material.frction=0.3"])
    assert "material.friction" in error_of({}, ["material.friction=-3"])
    with pytest.raises(ConfigError, match="key.sub=value"):
        build_config({}, ["material.friction"])
    with pytest.raises(ConfigError, match="not a section"):
        build_config({"seed": 1}, ["seed.value=3"])


def test_set_strings_are_parsed_once_and_written_back_the_same():
    sets = ["material.friction=0.3", "loading.normal_stress=24 MPa", "fluid.solver = auto", "output.slip_frames=12"]
    parsed = parse_overrides(sets)
    assert parsed == {"material.friction": 0.3, "loading.normal_stress": "24 MPa", "fluid.solver": "auto",
                      "output.slip_frames": 12}
    assert parse_overrides([format_override(k, v) for k, v in parsed.items()]) == parsed
    assert build_config({}, parsed) == build_config({}, sets)
    with pytest.raises(ConfigError, match="dotted name"):
        parse_overrides(["material..friction=1"])


def test_overrides_do_not_mutate_input():
    data = {"material": {"friction": 0.6}}
    build_config(data, ["material.friction=0.3"])
    assert data == {"material": {"friction": 0.6}}


@pytest.mark.parametrize("value", ["none", "None", "NONE", None])
def test_fluid_none(value):
    assert build_config({"fluid": value}).fluid is None


def test_fluid_section_defaults():
    cfg = build_config({"fluid": {}})
    assert cfg.fluid.permeability == 1e-5 and cfg.fluid.solver == "auto"


def test_load_config(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text("material:\n  friction: 0.4\nloading:\n  normal_stress: 24 MPa\nfluid: none\n")
    cfg = load_config(path, ["seed=3"])
    assert cfg.name == "scene" and cfg.seed == 3 and cfg.material.friction == 0.4
    assert cfg.loading.normal_stress == pytest.approx(3e-4) and cfg.fluid is None
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "missing.yaml")
    bad = tmp_path / "list.yaml"
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_config(bad)


def test_dt_bound():
    cfg = build_config({})
    bound = stability_bound(cfg)
    assert bound.mode == "tangential-rotational"
    # physics.md section 5: critical step 1.3-1.8 t0 for d = 1 at sigma = 3e-4; the bound
    # takes the smallest grains (d_min = 0.8) and a 10x chain force, so it is below that
    assert 0.5 < bound.bound < 1.8
    assert choose_dt(cfg) == pytest.approx(0.1 * bound.bound)
    ok = build_config({"numerics": {"dt": 0.99 * bound.bound}})
    assert choose_dt(ok) == 0.99 * bound.bound
    over = build_config({"numerics": {"dt": 1.01 * bound.bound}})
    with pytest.raises(ConfigError) as info:
        choose_dt(over)
    msg = str(info.value)
    assert "numerics.dt" in msg and f"{bound.bound:.4g}" in msg
    # the bound falls with the load: a dt fine at low stress is refused at high stress
    high = build_config({"numerics": {"dt": 0.5 * bound.bound}, "loading": {"normal_stress": 3e-2}})
    assert stability_bound(high).bound < stability_bound(cfg).bound
    with pytest.raises(ConfigError, match=f"{stability_bound(high).bound:.4g}"):
        choose_dt(high)


def test_tutorial_scene_is_the_demo_cut_short():
    """configs/tutorial.yaml is the demo but for its name and a shorter run: the same trajectory
    (same grains, seed, loading, wall mass, numerics), so the tutorials' slips are the demo's."""
    from gouge_cli.config import load_config

    root = Path(__file__).resolve().parents[2] / "configs"
    demo, tutorial = load_config(root / "demo.yaml").to_dict(), load_config(root / "tutorial.yaml").to_dict()
    assert tutorial["run"]["duration"] < demo["run"]["duration"]
    for d in (demo, tutorial):
        d.pop("name")
        d["run"].pop("duration")
    assert tutorial == demo
