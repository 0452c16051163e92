"""Run configuration: pydantic models loaded from YAML, with dotted overrides.

Every field has a default, a unit and a range. Dimensional fields accept a plain
dimensionless number (scales of docs/physics/units.md) or an SI string such as
``"24 MPa"``. Unknown keys, wrong types and out-of-range values raise
:class:`ConfigError` whose message names the key, the value and what is allowed.
"""

from __future__ import annotations

import sys

import copy
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Optional

import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator, model_validator

from .errors import bounded, clip, ConfigError
from .units import Scales, to_dimensionless

MAX_DEPTH = 8           # nesting of a config file (sections are 2 deep)
MAX_FILE_BYTES = 1_000_000


def _quantity(dimension: str):
    def convert(value: Any, info) -> Any:
        if value is None:
            return None
        scales = (info.context or {}).get("scales", Scales())
        return to_dimensionless(value, dimension, scales)

    convert.dimension = dimension       # read by gouge_cli.config_doc (schema, commented defaults)
    return BeforeValidator(convert)


Stress = Annotated[float, _quantity("stress")]
Velocity = Annotated[float, _quantity("velocity")]
Time = Annotated[float, _quantity("time")]
Length = Annotated[float, _quantity("length")]
Permeability = Annotated[float, _quantity("permeability")]
StiffnessPerLength = Annotated[float, _quantity("stiffness_per_length")]
MassPerLength = Annotated[float, _quantity("mass_per_length")]
Viscosity = Annotated[float, _quantity("viscosity")]
Compressibility = Annotated[float, _quantity("compressibility")]


class _Section(BaseModel):
    # strict: a boolean is not a number, "0.5" is not a float (SI strings go through _quantity);
    # no inf/nan anywhere (no field documents an infinite value)
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True, strict=True,
                              allow_inf_nan=False)


class ScalesConfig(_Section):
    """SI size of the units (Table 1 of the thesis). Used to read SI strings and written to outputs."""

    length_m: float = Field(5e-4, gt=0, description="mean grain diameter d [m]")
    stress_pa: float = Field(8e10, gt=0, description="Young's modulus E [Pa]")
    density_kg_m3: float = Field(2460.0, gt=0, description="grain density rho_s [kg/m3]")

    def scales(self) -> Scales:
        return Scales(self.length_m, self.stress_pa, self.density_kg_m3)


class MaterialConfig(_Section):
    """Grain material (thesis Table 1, Eqs. 8-11)."""

    youngs_modulus: Stress = Field(1.0, gt=0, description="E [E]")
    poisson_ratio: float = Field(0.2, ge=0, lt=0.5, description="nu [-]")
    density: float = Field(1.0, gt=0, description="grain density [rho_s]")
    friction: float = Field(0.5, ge=0, le=10, description="Coulomb friction mu at contacts [-]")
    damping: float = Field(0.05, ge=0, le=10, description="normal dashpot rate gamma, F = -gamma m_ij v_n [1/t0]")
    tangential_stiffness_factor: float = Field(
        1.0, gt=0, le=10, description="multiplies the thesis k_s = 2^1.5 E/((2-nu)(1+nu)) sqrt(R xi) [-]"
    )


class PackingConfig(_Section):
    """Seeded polydisperse packing between two rough walls (one row of glued grains each)."""

    n_grains: int = Field(2000, ge=20, le=5_000_000, description="total grains, wall grains included")
    width: Optional[Length] = Field(
        None, gt=0, description="periodic length L_x [d]; default 200 sqrt(n_grains/1e4) (4:1 layer)"
    )
    diameter_min: float = Field(0.8, gt=0, description="smallest diameter [d]")
    diameter_max: float = Field(1.2, gt=0, description="largest diameter [d]")
    wall_spacing: float = Field(1.0, gt=0.2, le=2.0, description="centre spacing of wall grains [d]")
    initial_spacing: float = Field(1.25, ge=1.0, le=3.0, description="lattice spacing of the loose start [d]")

    @model_validator(mode="after")
    def _diameters(self):
        if self.diameter_max < self.diameter_min:
            raise ValueError(
                f"diameter_max ({self.diameter_max}) must be >= diameter_min ({self.diameter_min})"
            )
        if self.initial_spacing < self.diameter_max:
            raise ValueError(
                f"initial_spacing ({self.initial_spacing}) must be >= diameter_max ({self.diameter_max}) "
                "so the loose start has no overlaps"
            )
        return self

    def resolved_width(self) -> float:
        return self.width if self.width is not None else float(round(200.0 * math.sqrt(self.n_grains / 1e4)))


class CompactionConfig(_Section):
    """Settling under the normal stress alone before the driver starts (docs/physics/walls.md)."""

    damping: float = Field(0.01, ge=0, le=1, description="background viscous rate on free grains while settling [1/t0]")
    min_time: Time = Field(500.0, ge=0, description="settle at least this long [t0]")
    max_time: Time = Field(5e4, gt=0, description="give up settling after this long [t0]")
    wall_velocity_tol: float = Field(
        1e-2, gt=0, description="settled when |v_z| of the top wall < tol * v_ref, v_ref = sigma/sqrt(E rho) [-]"
    )

    @model_validator(mode="after")
    def _times(self):
        if self.min_time > self.max_time:
            raise ValueError(f"min_time ({self.min_time:g}) must be <= max_time ({self.max_time:g})")
        return self


class LoadingConfig(_Section):
    """Top wall: constant normal stress, pulled by a spring at constant velocity (per unit length)."""

    normal_stress: Stress = Field(3e-4, gt=0, le=0.1, description="sigma [E] (thesis 'Normal Force')")
    spring_constant: StiffnessPerLength = Field(5e-7, gt=0, le=1.0, description="k per unit wall length [E/d]")
    velocity: Velocity = Field(1e-5, gt=0, le=0.1, description="loading velocity V_s [v0]")
    wall_mass: Optional[MassPerLength] = Field(
        None, gt=0, description="top-wall mass per unit length m_b [rho d^2]; default: its grains' mass"
    )


class NumericsConfig(_Section):
    """Time step, neighbour list and threads (docs/physics/timestep.md)."""

    dt: Optional[Time] = Field(None, gt=0, description="time step [t0]; default dt_safety * stability bound")
    dt_safety: float = Field(0.1, gt=0, le=1.0, description="fraction of the stability bound used as dt [-]")
    skin: float = Field(0.2, gt=0, le=2.0, description="Verlet skin [d]")
    threads: int = Field(
        0, ge=0, le=1024,
        description="numba threads; 0 = auto: 1 below 2000 grains (parallel regions cost more than they "
                    "save there), else all cores")
    device: Literal["cpu", "gpu"] = Field(
        "cpu",
        description="where the dry steps run: cpu (numba threads) or gpu (numba-cuda, one CUDA device; pip install "
                    "'gouge[gpu]'); the GPU's own runs repeat bit for bit, but its trajectory parts from the cpu's "
                    "at round-off (docs: performance); steps with a pore fluid and forks run on the cpu")
    sort_every: Optional[int] = Field(
        None, ge=0, le=1_000_000,
        description="re-number the grains by position every this many neighbour-list rebuilds, so that "
                    "neighbours stay close in memory as the layer shears; 0 = never; default 20 from "
                    "2000 grains, else 0")
    # stick scaling (gouge_cli.driver.stick_scaling)
    stick_scaling: float = Field(
        1.0, ge=1.0, le=1.0e4,
        description="inertia (density) scaling lambda of grains and walls while a loading run sticks: the "
                    "step grows by sqrt(lambda); every slip is recomputed at true inertia, forks are never "
                    "scaled; 1 = off [-]")
    stick_inertial_max: float = Field(
        1.0e-3, gt=0, le=0.1,
        description="bound on the inertial number I = (|v_wall|/H) d sqrt(lambda rho/sigma) in scaled "
                    "stretches; above it lambda is lowered until the next slip [-]")
    stick_deborah_max: float = Field(
        0.01, gt=0, le=10.0,
        description="wet loading runs: bound on the stick-phase Deborah number sqrt(lambda) l V_s / D; "
                    "a larger one is refused, and lambda is lowered when the measured one exceeds it [-]")


class RunConfig(_Section):
    duration: Time = Field(1e5, gt=0, description="simulated time after compaction [t0]")


class OutputConfig(_Section):
    series_interval: Time = Field(10.0, gt=0, description="time-series cadence [t0]")
    snapshot_interval: Time = Field(1e4, gt=0, description="grain-snapshot cadence [t0]")
    checkpoint_interval: Time = Field(2e4, gt=0, description="cadence of checkpoints/latest.h5 for resume [t0]")
    slip_frames: int = Field(
        0, ge=0, le=10_000,
        description="extra snapshots per predicted slip duration pi sqrt(m_b/k) while the top wall slips "
                    "(v_w >= slips.end_factor V_s), for movies; 0 = none; forks use 30 unless set [-]")


class SlipsConfig(_Section):
    """Slip detection and the checkpoint kept before each slip (velocity thresholds relative to V_s).
    These defaults are the slip rule's everywhere (model.slip_rule.SlipRule takes them from here)."""

    start_factor: float = Field(10.0, gt=1, description="an event triggers when v_wall >= start_factor V_s [-]")
    end_factor: float = Field(2.0, gt=0, description="an event spans v_wall >= end_factor V_s [-]")
    min_duration: Time = Field(0.0, ge=0, description="drop events shorter than this [t0]")
    min_slip: Length = Field(0.0, ge=0, description="drop events slipping less than this [d]")
    merge_gap: Time = Field(0.0, ge=0, description="events closer than this merge into one slip [t0]")
    lead_stress: float = Field(
        0.005, gt=0, le=0.2,
        description="checkpoint lead as a drop of tau/sigma: lead = lead_stress sigma / (k V_s) [-]")
    lead: Optional[Time] = Field(None, gt=0, description="checkpoint lead time before onset [t0]; overrides lead_stress")
    ring: int = Field(6, ge=2, le=100, description="in-memory states kept, spaced lead/4 apart [-]")

    @model_validator(mode="after")
    def _factors(self):
        if self.end_factor >= self.start_factor:
            raise ValueError(f"end_factor ({self.end_factor}) must be below start_factor ({self.start_factor})")
        return self


class FluidConfig(_Section):
    """Pore fluid on a Goren pressure grid (thesis Eqs. 14-20, docs/physics/fluid.md)."""

    permeability: Permeability = Field(
        1e-5, gt=0, description="Carman-Kozeny prefactor kappa_c [d^2] (thesis 'Permeability')"
    )
    compressibility: Compressibility = Field(36.0, gt=0, description="beta [1/E] (4.5e-10 1/Pa)")
    viscosity: Viscosity = Field(1.43e-7, gt=0, description="eta [E t0] (1e-3 Pa s)")
    filter_width: Length = Field(
        3.0, ge=0, le=40,
        description="[d] coarse-graining width w, a physical parameter of the model (the thesis's 'a few grains'): "
                    "solid fraction, solid velocity and drag are averaged with a Gaussian of standard deviation w/2 "
                    "that conserves the solid area, the drag going back through its transpose; 0: no filter, the "
                    "grid cell is the averaging width (the answers then depend on cell_size)")
    cell_size: Optional[Length] = Field(
        None, ge=0.25, le=20,
        description="[d] pressure-grid spacing h, a numerical parameter: at a fixed filter_width the answers "
                    "converge as h falls (docs/validation.md); default filter_width / 2, at most filter_width")
    solver: Literal["auto", "implicit", "explicit"] = Field(
        "auto", description="pressure time stepping: implicit (backward Euler, conjugate gradients), explicit "
                            "(forward Euler, sub-stepped to explicit_safety x the FTCS bound), or auto: one "
                            "second-order explicit (Heun) step while dt_f <= 0.25 x the FTCS bound (where its error "
                            "is at most a third of backward Euler's), implicit otherwise")
    step: Time = Field(
        0.5, gt=0, le=1000,
        description="[t0] fluid update period dt_f, rounded to whole DEM steps; between updates the drag is "
                    "that of the pressure extrapolated to the interval's middle (accuracy: `gouge accuracy`, "
                    "ladder fluid.step)")
    explicit_safety: float = Field(0.5, gt=0, le=1.0, description="fraction of the FTCS bound per sub-step [-]")

    @model_validator(mode="after")
    def _two_scales(self):
        if self.filter_width == 0 and self.cell_size is None:
            raise ValueError("fluid.filter_width 0 (no filter) needs fluid.cell_size, the averaging width then")
        if self.filter_width == 0 and self.cell_size < 2.0:
            raise ValueError(f"fluid.cell_size {self.cell_size:g} d without a filter (fluid.filter_width 0): cells "
                             "below 2 d are then the averaging width and make the undrained coupling unstable; "
                             "give a fluid.filter_width (e.g. 3) and refine the grid under it instead")
        if self.filter_width > 0 and self.cell_size is not None and self.cell_size > self.filter_width:
            raise ValueError(f"fluid.cell_size ({self.cell_size:g} d) must not exceed fluid.filter_width "
                             f"({self.filter_width:g} d): the grid must resolve the averaging width")
        return self

    @property
    def grid_spacing(self) -> float:
        """h [d]: cell_size, or half the filter width when it is not given."""
        return self.cell_size if self.cell_size is not None else 0.5 * self.filter_width


class Config(_Section):
    """A whole run. Written, fully resolved, next to every output."""

    name: str = Field("run", pattern=r"^[A-Za-z0-9_.-]+$", max_length=100,
                      description="run name, a plain file name (no '/', not '.' or '..'); output under runs/<name>/")
    seed: int = Field(1, ge=0, le=2**63 - 1, description="random seed of the packing (a 64-bit signed integer)")
    scales: ScalesConfig = ScalesConfig()
    material: MaterialConfig = MaterialConfig()
    packing: PackingConfig = PackingConfig()
    compaction: CompactionConfig = CompactionConfig()
    loading: LoadingConfig = LoadingConfig()
    numerics: NumericsConfig = NumericsConfig()
    run: RunConfig = RunConfig()
    output: OutputConfig = OutputConfig()
    slips: SlipsConfig = SlipsConfig()
    fluid: Optional[FluidConfig] = Field(None, description="absent or 'none' for a dry scene")

    @field_validator("name")
    @classmethod
    def _plain_name(cls, name: str) -> str:
        if name.strip(".") == "":
            raise ValueError("must be a plain name (letters, digits, '_', '-', '.'), not '.' or '..'")
        return name

    @model_validator(mode="before")
    @classmethod
    def _fluid_none(cls, data):
        if isinstance(data, dict) and isinstance(data.get("fluid"), str) and data["fluid"].lower() == "none":
            data = dict(data)
            data["fluid"] = None
        return data

    def to_dict(self) -> dict:
        return self.model_dump(mode="json")


def _as_written(data: dict, loc: tuple):
    """The value the user wrote at `loc` (before unit conversion), if there is one."""
    node = data
    for part in loc:
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def _format_errors(err: ValidationError, data: dict, prefix: tuple = ()) -> str:
    lines = []
    for e in err.errors():
        loc = prefix + tuple(e["loc"])
        key = ".".join(str(p) for p in loc) or "(top level)"
        if e["type"] == "extra_forbidden":
            lines.append(f"{clip(key, 120)}: unknown key (check the spelling; see `gouge config --defaults`)")
            continue
        value = e.get("input")
        written = _as_written(data, loc)
        shown = f"{clip(repr(written), 80)} (= {clip(repr(value), 80)} dimensionless)" \
            if isinstance(written, str) and written != value else clip(repr(value), 80)
        msg = clip(e["msg"].removeprefix("Value error, "), 300)
        lines.append(f"{clip(key, 120)} = {shown}: {msg}")
    return bounded("invalid config:\n  " + "\n  ".join(lines))


class _StrictLoader(yaml.SafeLoader):
    """safe_load that refuses duplicate keys, anchors/aliases (no 'billion laughs') and deep nesting."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent) or getattr(self.peek_event(), "anchor", None):
            mark = self.peek_event().start_mark
            raise ConfigError(f"line {mark.line + 1}: YAML anchors and aliases (&, *) are not allowed in a config")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise ConfigError(f"line {mark.line + 1}: nested more than {MAX_DEPTH} levels deep")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                raise ConfigError(f"line {key_node.start_mark.line + 1}: key {clip(repr(key), 40)} is not a "
                                  "name (keys are section and field names)")
            if key in seen:
                raise ConfigError(f"line {key_node.start_mark.line + 1}: duplicate key {clip(key, 80)!r} "
                                  "(each key may appear once per section)")
            seen.add(key)
        return super().construct_mapping(node, deep)


def parse_yaml(text: str, what: str):
    """YAML text -> Python data with the rules of _StrictLoader; ConfigError naming `what`."""
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except ConfigError as err:
        raise ConfigError(f"{what}: {err}") from None
    except yaml.YAMLError as err:
        raise ConfigError(bounded(f"{what}: not valid YAML: {clip(err, 300)}")) from None


def _parse_value(text: str) -> Any:
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except (yaml.YAMLError, ConfigError):
        return text


def _override_key(key: str, item: str) -> list[str]:
    parts = key.split(".")
    if not key or any(not part for part in parts):
        raise ConfigError(f"override {clip(repr(item), 80)}: the key before '=' must be a dotted name such as "
                          "loading.velocity")
    return parts


def parse_overrides(items: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """``--set`` strings ``key.sub=value`` -> {dotted key: value parsed as YAML} (a later key wins);
    ConfigError naming a malformed one. The CLI parses here once; workflows take the dict."""
    parsed = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"override {clip(repr(item), 80)} is not of the form key.sub=value")
        key, value = item.split("=", 1)
        key = key.strip()
        _override_key(key, item)
        parsed[key] = _parse_value(value.strip())
    return parsed


def format_override(key: str, value: Any) -> str:
    """The ``--set`` string of one parsed override (parse_overrides' inverse), for a command line."""
    return f"{key}={yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...').strip()}"


def apply_overrides(data: dict, overrides: dict[str, Any] | list[str]) -> dict:
    """Apply {dotted key: value} overrides (``--set`` strings are parsed first: parse_overrides)
    to a raw config dict."""
    data = copy.deepcopy(data)
    if not isinstance(overrides, dict):
        overrides = parse_overrides(overrides)
    for key, value in overrides.items():
        parts = _override_key(key, f"{key}={value}")
        node = data
        for depth, part in enumerate(parts[:-1]):
            child = node.get(part)
            if child is None or isinstance(child, str):
                child = {}
                node[part] = child
            elif not isinstance(child, dict):
                raise ConfigError(f"override {clip(repr(key), 80)}: {'.'.join(parts[:depth + 1])} is not a section")
            node = child
        node[parts[-1]] = value
    return data


def build_config(data: dict | None, overrides: list[str] | dict | None = None) -> Config:
    """Validate a raw dict (plus overrides) into a frozen Config, or raise ConfigError."""
    data = dict(data or {})
    if overrides:
        data = apply_overrides(data, overrides)
    try:
        scales = ScalesConfig.model_validate(data.get("scales") or {}).scales()
    except ValidationError as err:
        raise ConfigError(_format_errors(err, data, ("scales",))) from None
    try:
        return Config.model_validate(data, context={"scales": scales})
    except ValidationError as err:
        raise ConfigError(_format_errors(err, data)) from None


def not_a_file(path: Path) -> str | None:
    """What `path` is when it exists but is no regular file (a directory, a device, a FIFO, a
    socket), or None."""
    import stat

    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    for test, what in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return None


def find_config(name: str | Path) -> Path:
    """A config path, or a scene name looked up as configs/<name>.yaml and configs/thesis/<name>.yaml."""
    path = Path(name)
    if path.is_file():
        return path
    kind = not_a_file(path)
    if kind is not None:
        raise ConfigError(f"config file {str(path)!r} is {kind}, not a file; give a YAML config file")
    roots = [Path.cwd() / "configs", Path(__file__).resolve().parents[1] / "configs",
             Path(sys.prefix) / "share" / "gouge" / "configs"]          # (a wheel's: pyproject data-files)
    for root in roots:
        for candidate in (root / f"{name}.yaml", root / "thesis" / f"{name}.yaml", root / f"{name}"):
            if candidate.is_file():
                return candidate
    shipped = [c for root in roots for c in root.rglob(f"{path.stem}.yaml")]
    hint = f"; did you mean {shipped[0]} (or the scene name {path.stem!r})?" if shipped else \
        f"; scene names are looked up in {' and '.join(str(r) for r in dict.fromkeys(roots))} (and thesis/)"
    raise ConfigError(f"config file {str(path)!r} does not exist in {Path.cwd()}{hint}")


def load_config(path: str | Path, overrides: list[str] | dict | None = None) -> Config:
    """Read a config file (a UTF-8 YAML mapping: no duplicate keys, anchors or aliases) and validate
    it with overrides (``["loading.normal_stress=24 MPa"]`` or a dict)."""
    path = find_config(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise ConfigError(f"{path}: cannot be read ({err.strerror or err})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError(f"{path}: {len(raw)} bytes; a config is a short text file (at most {MAX_FILE_BYTES})")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not UTF-8 text (byte {err.start}); a config is a YAML text file") from None
    data = parse_yaml(text, str(path))
    if data is None:
        raise ConfigError(f"{path}: the file is empty; give at least one section (see `gouge config --defaults`)")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of sections (name: ..., packing: ...), "
                          f"not {type(data).__name__} {clip(repr(data), 60)}")
    data.setdefault("name", path.stem)
    return build_config(data, overrides)


def dump_config(config: Config) -> str:
    return yaml.safe_dump(config.to_dict(), sort_keys=False)
