"""One scene (gouge_cli.model.scene): its construction is the preflight check, and what it derives
is what the Simulation runs."""

from __future__ import annotations

import numpy as np
import pytest

from gouge_cli.config import build_config
from gouge_cli.driver.simulation import Simulation
from gouge_cli.errors import ConfigError
from gouge_cli.model.params import build_params, choose_threads
from gouge_cli.model.scene import Scene
from gouge_cli.model.timestep import choose_dt, contact_constants

SMALL = {"packing": {"n_grains": 60, "width": 8}}


def test_scene_derives_each_quantity_once_as_the_model_functions_do():
    cfg = build_config(SMALL)
    scene = Scene(cfg)
    assert scene.dt == choose_dt(cfg) == scene.preflight.dt
    assert (scene.c_normal, scene.c_tangential) == contact_constants(cfg)
    assert scene.threads == choose_threads(cfg.numerics.threads, cfg.packing.n_grains)
    assert np.array_equal(scene.params(8.0, 3.0, 60), build_params(cfg, scene.dt, 8.0, 3.0, 60))
    assert (scene.engine, scene.fallback) == ("cpu dry", "")
    wet = Scene(build_config({**SMALL, "fluid": {"permeability": 1e-5}}))
    assert wet.engine == "cpu wet" and wet.wet


def test_a_simulation_cannot_be_built_from_a_config_the_preflight_refuses():
    light = build_config({**SMALL, "loading": {"wall_mass": 1e-12}})
    with pytest.raises(ConfigError, match="loading.wall_mass"):
        Scene(light)
    with pytest.raises(ConfigError, match="loading.wall_mass"):
        Simulation(light)


def test_a_simulation_runs_its_scene():
    scene = Scene(build_config(SMALL))
    sim = Simulation(scene)
    assert sim.scene is scene and sim.config is scene.config
    assert sim.dt == scene.dt and sim.threads == scene.threads
    assert np.array_equal(Simulation(scene.config).params, sim.params)


def test_the_scene_names_the_engines_and_the_simulation_runs_them():
    """Engines chosen once by the Scene (driver.engines): the dry one from the start, the wet one
    from the moment the fluid starts; the Simulation itself never looks at the device or the fluid
    to decide how to step."""
    dry = Simulation(build_config(SMALL))
    assert (dry.scene.dry_engine, dry.scene.wet_engine, dry.engine.name) == ("cpu dry", None, "cpu dry")
    wet = Simulation(build_config({**SMALL, "fluid": {"permeability": 1e-5}}))
    assert (wet.scene.dry_engine, wet.scene.wet_engine, wet.engine.name) == ("cpu dry", "cpu wet", "cpu dry")
    wet.start_loading()
    assert wet.engine.name == "cpu wet" and wet.engine.kernel.py_func.__name__ == "advance_fluid"
    assert wet.gpu_fallback == ""
