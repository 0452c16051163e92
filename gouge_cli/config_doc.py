"""What a config may hold, read from the pydantic models of :mod:`gouge_cli.config`.

:func:`commented_defaults`: the default config as YAML with each key's unit, range and
description as a comment (the fluid section commented out: absent means a dry scene).
:func:`json_schema`: a JSON Schema (draft 2020-12) that editors use for completion and
checking; dimensional keys accept a number (dimensionless) or a string with an SI unit.
Units come from the ``[unit]`` in each field's description.
"""

from __future__ import annotations

import re
from typing import Any, Literal, get_args, get_origin

import yaml
from pydantic import BaseModel

from . import __version__
from .config import Config, FluidConfig
from .units import _UNITS

# the unit: the first "[...]" that does not follow a word (not the extra of "pip install 'gouge[gpu]'")
_UNIT = re.compile(r"\s*(?<![\w'\"])\[([^\]\s][^\]]*)\]")
_BOUNDS = (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
SCHEMA_ID = "https://gouge.invalid/config.schema.json"


def _dimension(field) -> str | None:
    for m in field.metadata:
        dim = getattr(getattr(m, "func", None), "dimension", None)
        if dim:
            return dim
    return None


def _bounds(field) -> dict:
    out = {}
    for m in field.metadata:
        for key, _ in _BOUNDS:
            if getattr(m, key, None) is not None:
                out[key] = getattr(m, key)
    return out


def _section_model(field):
    """The BaseModel class of a section field (Optional[...] unwrapped), else None."""
    ann = field.annotation
    for cand in (ann, *get_args(ann)):
        if isinstance(cand, type) and issubclass(cand, BaseModel):
            return cand
    return None


def split_description(text: str | None) -> tuple[str, str]:
    """(unit, description) from a field description holding ``[unit]`` (the first bracket that does
    not follow a word, so that ``gouge[gpu]`` is no unit); unit '' if none."""
    text = text or ""
    m = _UNIT.search(text)
    if not m:
        return "", text
    return m.group(1), (text[: m.start()] + text[m.end():]).strip()


def si_units(dimension: str) -> list[str]:
    return sorted(u for u, (_, dim) in _UNITS.items() if dim == dimension)


def _range_text(field) -> str:
    b = _bounds(field)
    parts = [f"{sym} {b[key]:g}" for key, sym in _BOUNDS if key in b]
    if get_origin(field.annotation) is Literal:
        parts.append("one of " + ", ".join(map(str, get_args(field.annotation))))
    return ", ".join(parts)


def _comment(field) -> str:
    unit, text = split_description(field.description)
    bits = [f"[{unit}]" if unit else "", _range_text(field), text]
    dim = _dimension(field)
    if dim:
        bits.append(f"(or SI: {', '.join(si_units(dim))})")
    return "  ".join(b for b in bits if b)


def _scalar(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("\n...").strip()


def _lines(model: type[BaseModel], values: dict, indent: int) -> list[str]:
    pad = "  " * indent
    rows = []
    for name, field in model.model_fields.items():
        sub = _section_model(field)
        if sub is not None:
            doc = (sub.__doc__ or "").strip().splitlines()[0] if sub.__doc__ else ""
            if values.get(name) is None:
                continue                      # optional section left out (fluid): written separately
            rows.append((f"{pad}{name}:", doc))
            rows += _lines(sub, values[name], indent + 1)
        else:
            rows.append((f"{pad}{name}: {_scalar(values.get(name))}", _comment(field)))
    return rows


def commented_defaults() -> str:
    """The default config as YAML, one key a line with ``# [unit] range  description``."""
    defaults = Config().to_dict()
    rows = _lines(Config, defaults, 0)
    fluid_field = Config.model_fields["fluid"]
    fluid_rows = [(f"fluid:", (FluidConfig.__doc__ or "").strip().splitlines()[0])]
    fluid_rows += _lines(FluidConfig, FluidConfig().model_dump(mode="json"), 1)
    width = max(len(r[0]) for r in rows + fluid_rows) + 2
    head = [f"# gouge {__version__}: every config key with its default, unit, allowed range and meaning.",
            "# Units are dimensionless (docs/physics/units.md): length d, stress E, density rho_s,",
            "# time t0 = d / sqrt(E / rho_s), velocity v0 = d / t0; keys marked 'or SI' also take a",
            "# string with an SI unit, e.g. normal_stress: 24 MPa. Unknown keys are refused."]
    body = [f"{text:<{width}}# {note}" if note else text for text, note in rows]
    fluid = ["", f"# fluid: {fluid_field.description}. For a wet scene uncomment this section",
             "# (the values shown are the defaults of each key):"]
    fluid += [f"# {text:<{width}}# {note}" if note else f"# {text}" for text, note in fluid_rows]
    return "\n".join(head + body + fluid) + "\n"


def _patch_quantities(model: type[BaseModel], schema: dict, defs: dict) -> None:
    """Let each dimensional key of ``model`` take an SI string too; add units to descriptions."""
    props = schema.get("properties", {})
    for name, field in model.model_fields.items():
        sub = _section_model(field)
        if sub is not None:
            _patch_quantities(sub, defs[sub.__name__], defs)
            continue
        prop = props.get(name)
        if prop is None:
            continue
        unit, _ = split_description(field.description)
        if unit:
            prop["x-unit"] = unit
        dim = _dimension(field)
        if dim:
            number = {k: v for k, v in prop.items() if k in ("type", "exclusiveMinimum", "minimum",
                                                             "exclusiveMaximum", "maximum", "anyOf")}
            for k in number:
                prop.pop(k)
            units = "|".join(re.escape(u) for u in si_units(dim))
            prop["anyOf"] = [number if "anyOf" not in number else {"anyOf": number["anyOf"]},
                             {"type": "string",
                              "pattern": rf"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*({units})?\s*$",
                              "description": f"a number with an SI unit: {', '.join(si_units(dim))}"}]


def json_schema() -> dict:
    """JSON Schema of a config file (pydantic's, with SI strings allowed and ``fluid: none``)."""
    schema = Config.model_json_schema(mode="validation")
    defs = schema.setdefault("$defs", {})
    _patch_quantities(Config, schema, defs)
    fluid = schema["properties"]["fluid"]
    fluid["anyOf"] = [{"$ref": "#/$defs/FluidConfig"}, {"type": "null"},
                      {"type": "string", "enum": ["none", "None", "NONE"]}]
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["$id"] = SCHEMA_ID
    schema["title"] = f"gouge run config (gouge {__version__})"
    return schema


def key_rows() -> list[dict]:
    """Every config key as a row (the docs' reference table): section, section_doc, key (dotted),
    default, unit, range, meaning (with the SI units a dimensional key also takes)."""
    rows = []

    def walk(model: type[BaseModel], values: dict, prefix: str, section: str, section_doc: str):
        for name, field in model.model_fields.items():
            sub = _section_model(field)
            if sub is not None:
                doc = (sub.__doc__ or "").strip().splitlines()[0] if sub.__doc__ else ""
                if field.description:
                    doc = f"{doc} {field.description}."
                sub_values = values.get(name) or sub().model_dump(mode="json")
                walk(sub, sub_values, f"{prefix}{name}.", f"{prefix}{name}", doc)
                continue
            unit, text = split_description(field.description)
            dim = _dimension(field)
            if dim:
                text = f"{text} (or SI: {', '.join(si_units(dim))})"
            rows.append({"section": section, "section_doc": section_doc, "key": prefix + name,
                         "default": _scalar(values.get(name)), "unit": unit, "range": _range_text(field),
                         "meaning": text})

    walk(Config, Config().to_dict(), "", "", (Config.__doc__ or "").strip().splitlines()[0])
    return rows
