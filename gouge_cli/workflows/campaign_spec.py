"""The campaign file (`gouge campaign SPEC.yaml`) and its expansion into sweep points.

A spec names a base config, a sweep and what to do at each point::

    name: phase                      # output under <out>/<name>/ (default out: campaigns)
    base: configs/demo.yaml          # path (relative to the spec file or the working directory) or scene name
    set: {run.duration: 60000}       # dotted overrides applied at every point
    sweep:
      grid:                          # cartesian product, in the order written
        loading.normal_stress: [2.0e-4, 3.0e-4]
      points:                        # and/or explicit points (each a mapping of dotted overrides)
        - {loading.velocity: 2.0e-5}
      seeds: [1, 2]                  # every point once per seed (default: the base config's seed)
    action: study                    # run | study (run, then fork every slip kept with a checkpoint)
    study: {permeabilities: [1.0e-5, 1.0e-3], duration: null}
    phase: {x: permeability, y: loading.normal_stress}   # axes of the phase diagram

Validated by pydantic models with ``extra="forbid"`` (unknown keys are refused, naming them);
every point's config is validated too, so a bad override stops the campaign before anything
runs. A point's directory name is derived from its overrides but never read back: what a point
contains is in its state-point file (see :mod:`gouge_cli.workflows.campaign`).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Optional

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..config import Config, find_config, load_config
from ..errors import ConfigError, SpecError


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _plain(value: Any) -> Any:
    """YAML 1.1 reads 1e-5 as a string; take such strings as the number they spell."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def _check_keys(keys, where: str):
    for key in keys:
        if not isinstance(key, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*", key):
            raise ValueError(f"{where}: {key!r} is not a dotted config key such as loading.normal_stress")
        if key == "name":
            raise ValueError(f"{where}: 'name' is set per point by the campaign")
        if key == "seed":
            raise ValueError(f"{where}: sweep the seed with sweep.seeds")


class Sweep(_Section):
    grid: dict[str, list[Any]] = Field(default_factory=dict, description="dotted key -> values (cartesian product)")
    points: list[dict[str, Any]] = Field(default_factory=list, description="explicit points: dotted key -> value")
    seeds: list[int] = Field(default_factory=list, description="every point once per seed (default: base seed)")

    @field_validator("grid")
    @classmethod
    def _grid(cls, grid):
        _check_keys(grid, "sweep.grid")
        for key, values in grid.items():
            if not values:
                raise ValueError(f"sweep.grid.{key}: give at least one value")
        return {k: [_plain(v) for v in vs] for k, vs in grid.items()}

    @field_validator("points")
    @classmethod
    def _points(cls, points):
        for i, p in enumerate(points):
            _check_keys(p, f"sweep.points[{i}]")
        return [{k: _plain(v) for k, v in p.items()} for p in points]

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, seeds):
        if any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
            raise ValueError("sweep.seeds: distinct non-negative integers")
        return seeds


class Study(_Section):
    permeabilities: list[float] = Field(..., min_length=1, description="kappa_c [d^2] of the undrained branches")
    duration: Optional[float] = Field(None, gt=0, description="branch length [t0]; default: until its first slip ends")

    @field_validator("permeabilities", mode="before")
    @classmethod
    def _perms(cls, values):
        values = [_plain(v) for v in (values or [])]
        if any(not isinstance(v, (int, float)) or not v > 0 for v in values):
            raise ValueError("study.permeabilities: positive numbers (kappa_c in d^2, e.g. 1.0e-5)")
        return sorted(set(float(v) for v in values))


class Phase(_Section):
    x: str = Field("permeability", description="'permeability' (of the undrained branch) or a swept key")
    y: str = Field("loading.normal_stress", description="'permeability' or a swept key")


class CampaignSpec(_Section):
    name: str = Field(..., pattern=r"^[A-Za-z0-9_.-]+$", description="campaign name; output under <out>/<name>/")
    base: str = Field(..., description="base config: a path or a scene name")
    set: dict[str, Any] = Field(default_factory=dict, description="dotted overrides at every point")
    sweep: Sweep = Sweep()
    action: Literal["run", "study"] = "run"
    study: Optional[Study] = None
    out: str = Field("campaigns", description="folder holding <name>/")
    phase: Phase = Phase()

    @field_validator("set")
    @classmethod
    def _set(cls, values):
        _check_keys(values, "set")
        return {k: _plain(v) for k, v in values.items()}

    @model_validator(mode="after")
    def _study(self):
        if self.action == "study" and self.study is None:
            raise ValueError("action 'study' needs a study section: study: {permeabilities: [1.0e-5]}")
        if self.action == "run" and self.study is not None:
            raise ValueError("a study section is given but action is 'run'; set action: study")
        return self

    def swept_keys(self) -> list[str]:
        """Dotted keys that vary between points (seed last when several seeds are swept)."""
        keys = list(self.sweep.grid)
        for p in self.sweep.points:
            keys += [k for k in p if k not in keys]
        return keys + (["seed"] if len(self.sweep.seeds) > 1 else [])


@dataclass(frozen=True)
class Point:
    """One sweep point: its overrides (dotted key -> value as written) and its resolved config."""

    name: str
    overrides: dict
    config: Config
    base: Path
    fixed: dict

    def command(self, run_dir: Path) -> str:
        """The `gouge run` that produces this point's run bit for bit."""
        sets = {**self.fixed, **self.overrides, "name": self.name}
        args = ["gouge", "run", str(self.base)]
        for key, value in sets.items():
            args += ["--set", f"{key}={yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...').strip()}"]
        return shlex.join(args + ["--out", str(run_dir)])


def _format(err: ValidationError, path: Path) -> str:
    lines = []
    for e in err.errors():
        key = ".".join(str(p) for p in e["loc"]) or "(top level)"
        if e["type"] == "extra_forbidden":
            lines.append(f"{key}: unknown key")
        elif e["type"] == "missing":
            lines.append(f"{key}: required")
        else:
            lines.append(f"{key}: {e['msg'].removeprefix('Value error, ')}")
    return f"invalid campaign file {path}:\n  " + "\n  ".join(lines) + \
        "\n  (keys: name, base, set, sweep {grid, points, seeds}, action, study {permeabilities, duration}, out, phase {x, y})"


def load_spec(path: str | Path) -> CampaignSpec:
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"campaign file {path} does not exist")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise SpecError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise SpecError(f"{path}: the top level must be a mapping (name, base, sweep, ...)")
    try:
        return CampaignSpec.model_validate(data)
    except ValidationError as err:
        raise SpecError(_format(err, path)) from None


def base_path(spec: CampaignSpec, spec_path: Path) -> Path:
    """The base config: relative to the spec file first, then as `gouge run` finds it."""
    beside = Path(spec_path).parent / spec.base
    return (beside if beside.is_file() else find_config(spec.base)).resolve()


def _label(value: Any) -> str:
    text = f"{value:g}" if isinstance(value, float) else str(value)
    return re.sub(r"[^A-Za-z0-9.+-]", "", text)


def point_name(overrides: dict) -> str:
    """Readable directory name plus a hash of the overrides (never parsed back)."""
    digest = hashlib.sha256(json.dumps(overrides, sort_keys=True, default=str).encode()).hexdigest()[:8]
    slug = "_".join(f"{k.rsplit('.', 1)[-1]}-{_label(v)}" for k, v in overrides.items())[:80]
    return f"{slug}_{digest}" if slug else f"base_{digest}"


def expand(spec: CampaignSpec, spec_path: Path) -> list[Point]:
    """Every point of the sweep (grid, then listed points, each once per seed), configs validated."""
    base = base_path(spec, spec_path)
    grid = spec.sweep.grid
    combos = [dict(zip(grid, values)) for values in itertools.product(*grid.values())] if grid else []
    combos += [dict(p) for p in spec.sweep.points]
    if not combos:
        combos = [{}]
    seeds = spec.sweep.seeds or [None]
    points, seen = [], set()
    for combo in combos:
        for seed in seeds:
            overrides = dict(combo) if seed is None else {**combo, "seed": seed}
            name = point_name(overrides)
            if name in seen:
                continue
            seen.add(name)
            try:
                config = load_config(base, {**spec.set, **overrides, "name": name})
            except ConfigError as exc:
                raise SpecError(f"sweep point {overrides} (base {base}): {exc}") from None
            points.append(Point(name, overrides, config, base, dict(spec.set)))
    phase_axes(spec)
    return points


def phase_axes(spec: CampaignSpec) -> tuple[str, str | None]:
    """(x, y) of the phase diagram. Given axes must be swept; the default y (normal stress)
    falls back to the first swept key, or to none (one row) when nothing but seeds is swept."""
    axes = ["permeability"] + spec.swept_keys()
    if "phase" in spec.model_fields_set:
        for axis in (spec.phase.x, spec.phase.y):
            if axis not in axes:
                raise SpecError(f"phase: {axis!r} is not swept; choose from {', '.join(axes)}")
        return spec.phase.x, spec.phase.y
    others = [k for k in spec.swept_keys() if k != "seed"]
    y = spec.phase.y if spec.phase.y in others else (others[0] if others else None)
    return spec.phase.x, y
