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
    max_points: 10000                # refuse a larger sweep (counted before it is expanded)
    action: study                    # run | study (run, then fork every slip kept with a checkpoint)
    study: {permeabilities: [1.0e-5, 1.0e-3], duration: null}
    phase: {x: permeability, y: loading.normal_stress}   # axes of the phase diagram

Validated by pydantic models with ``extra="forbid"`` (unknown keys are refused, naming them);
an empty ``sweep``, ``sweep.grid`` or ``sweep.points`` is refused, naming it. The sweep is counted
before it is expanded, (grid product + listed points) x seeds, and refused above ``max_points``
(top-level key, default MAX_POINTS; ``gouge campaign --max-points N`` overrides it). Every point's
config is validated and pre-flighted (:class:`~gouge_cli.model.scene.Scene`) too, so a
bad override stops the campaign before anything runs. A point's directory name is derived from
its overrides but never read back: what a point contains is in its state-point file (see
:mod:`gouge_cli.workflows.campaign`).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Optional

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..config import MAX_FILE_BYTES, Config, find_config, load_config, not_a_file
from ..errors import ConfigError, SpecError
from ..model.scene import Scene


#: Most sweep points a campaign expands unless its spec's ``max_points`` (or --max-points) says otherwise.
MAX_POINTS = 10_000
MAX_SPEC_BYTES = MAX_FILE_BYTES     # like a config: read before parsing


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
        if not grid:
            raise ValueError("empty: give at least one dotted key with its values, or leave grid out")
        _check_keys(grid, "sweep.grid")
        for key, values in grid.items():
            if not values:
                raise ValueError(f"sweep.grid.{key}: give at least one value")
        return {k: [_plain(v) for v in vs] for k, vs in grid.items()}

    @field_validator("points")
    @classmethod
    def _points(cls, points):
        if not points:
            raise ValueError("empty: list at least one point (a mapping of dotted keys), or leave points out")
        for i, p in enumerate(points):
            if not p:
                raise ValueError(f"sweep.points[{i}]: empty point; give at least one dotted key")
            _check_keys(p, f"sweep.points[{i}]")
        return [{k: _plain(v) for k, v in p.items()} for p in points]

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, seeds):
        if any(not 0 <= s <= 2 ** 63 - 1 for s in seeds) or len(set(seeds)) != len(seeds):
            raise ValueError("sweep.seeds: distinct integers from 0 to 2**63 - 1")
        return seeds

    @model_validator(mode="after")
    def _not_empty(self):
        if not (self.grid or self.points or self.seeds):
            raise ValueError("empty sweep: give sweep.grid, sweep.points or sweep.seeds")
        return self

    def size(self) -> int:
        """Points of the sweep, counted without expanding it: (grid product + points) x seeds
        (points that coincide are run once, so the campaign may have fewer)."""
        grid = math.prod(len(values) for values in self.grid.values()) if self.grid else 0
        return ((grid + len(self.points)) or 1) * max(1, len(self.seeds))


class Study(_Section):
    permeabilities: list[float] = Field(..., min_length=1, description="kappa_c [d^2] of the undrained branches")
    duration: Optional[float] = Field(None, gt=0, description="branch length [t0]; default: until its first slip ends")
    skip_transient: bool = Field(False, description="fork only the slips after the run's transient "
                                 "(analysis.study.transient_slips)")
    variants: dict[str, dict[str, Any]] = Field(
        default_factory=dict,
        description="name -> dotted overrides of the undrained branches (e.g. {fluid.filter_width: 4}): every "
                    "slip is forked once per variant from the same packing; the first variant's forks are the "
                    "point's forks/, the others' under variants/<name>/ (the drained branch is shared)")

    @field_validator("variants")
    @classmethod
    def _variants(cls, variants):
        for name, overrides in variants.items():
            if not re.fullmatch(r"[A-Za-z0-9_-]+", str(name)):
                raise ValueError(f"study.variants: {name!r} is not a name (letters, digits, _ and -)")
            _check_keys(overrides, f"study.variants.{name}")
        return {str(k): {key: _plain(v) for key, v in o.items()} for k, o in variants.items()}

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
    sweep: Sweep = Field(..., description="grid, points and/or seeds: what varies between points")
    max_points: int = Field(MAX_POINTS, ge=1, description="refuse sweeps of more points than this")
    action: Literal["run", "study"] = "run"
    study: Optional[Study] = None
    out: str = Field("campaigns", description="folder holding <name>/")
    results: Optional[str] = Field(None, description="folder of the results records, one per finished piece "
                                   "(default <out>/<name>/results): copy or commit it; the tables are built from it")
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
    return (f"invalid campaign file {path}:\n  " + "\n  ".join(lines) +
            "\n  (keys: name, base, set, sweep {grid, points, seeds}, max_points, action, "
            "study {permeabilities, duration, skip_transient, variants}, out, results, phase {x, y})")


def check_size(spec: CampaignSpec, path: Path, max_points: int | None = None) -> int:
    """The sweep's point count; SpecError with the count when it exceeds ``max_points``
    (default: the spec's own ``max_points``)."""
    limit = spec.max_points if max_points is None else max_points
    n = spec.sweep.size()
    if n > limit:
        grid = " x ".join(str(len(v)) for v in spec.sweep.grid.values())
        parts = ([f"grid {grid}"] if grid else []) + ([f"{len(spec.sweep.points)} listed points"]
                                                      if spec.sweep.points else [])
        seeds = f", each x {len(spec.sweep.seeds)} seeds" if len(spec.sweep.seeds) > 1 else ""
        raise SpecError(f"{path}: sweep: {n:,} points ({' + '.join(parts) or 'base'}{seeds}) exceed max_points = "
                        f"{limit:,}; nothing was run. Sweep fewer values, or raise the limit (max_points: N in the "
                        "spec, or --max-points N)")
    return n


def load_spec(path: str | Path, max_points: int | None = None) -> CampaignSpec:
    """The validated spec (SpecError naming the key otherwise), its sweep counted and held to
    ``max_points`` (default: the spec's, see :func:`check_size`) before anything is expanded."""
    path = Path(path)
    if not path.is_file():
        kind = not_a_file(path)
        raise SpecError(f"campaign file {path} is {kind}, not a file" if kind else f"campaign file {path} does not exist")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_SPEC_BYTES + 1)      # the cap is checked before anything is parsed
    except OSError as exc:
        raise SpecError(f"campaign file {path} cannot be read ({exc.strerror or exc})") from None
    if len(raw) > MAX_SPEC_BYTES:
        raise SpecError(f"campaign file {path} is larger than {MAX_SPEC_BYTES:,} bytes; a campaign spec is a short "
                        "text file; sweep fewer values")
    try:
        data = yaml.safe_load(raw.decode("utf-8", errors="replace"))
    except yaml.YAMLError as exc:
        raise SpecError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise SpecError(f"{path}: the top level must be a mapping (name, base, sweep, ...)")
    try:
        spec = CampaignSpec.model_validate(data)
    except ValidationError as err:
        raise SpecError(_format(err, path)) from None
    if max_points is not None and max_points < 1:
        raise SpecError(f"--max-points {max_points}: give a positive number")
    check_size(spec, path, max_points)
    return spec


def base_path(spec: CampaignSpec, spec_path: Path) -> Path:
    """The base config: relative to the spec file first, then as `gouge run` finds it."""
    beside = Path(spec_path).parent / spec.base
    return (beside if beside.is_file() else find_config(spec.base)).resolve()


def _label(value: Any) -> str:
    text = f"{value:g}" if isinstance(value, float) else str(value)
    return re.sub(r"[^A-Za-z0-9.-]", "", text)          # a run name takes no "+" (2e+06 -> 2e06)


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
                Scene(config)       # the preflight checks
            except ConfigError as exc:
                raise SpecError(f"sweep point {overrides} (base {base}): {exc}") from None
            _check_variants(spec, config, overrides)
            points.append(Point(name, overrides, config, base, dict(spec.set)))
    phase_axes(spec)
    return points


def _check_variants(spec: CampaignSpec, config: Config, overrides: dict):
    """Each study variant's overrides on an undrained branch of the point (SpecError naming the variant)."""
    from ..config import build_config

    if not (spec.study and spec.study.variants):
        return
    data = config.to_dict()
    data["fluid"] = dict(data.get("fluid") or {}, permeability=spec.study.permeabilities[0])
    for name, changes in spec.study.variants.items():
        try:
            build_config(data, changes)
        except ConfigError as exc:
            raise SpecError(f"study.variants.{name} at sweep point {overrides}: {exc}") from None


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
