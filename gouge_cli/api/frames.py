"""The xarray and pandas pieces of the API's views: variable attributes with units, the lazy /series
column, the pair table's frame, and :func:`to_si` (values in units of the scales -> SI)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr
from xarray.backends import BackendArray
from xarray.core import indexing

from ..analysis.forkpairs import PAIR_COLUMNS, PAIR_UNITS
from ..io.filedoc import ANALYSIS_UNITS, SLIP_ATTRS
from ..io.runreader import read_series_items
from ..units import pint_unit, si_of, unit_sizes

_NAN = float("nan")
TIME_DOC = "time since loading began (stored clock minus the clock at the loading start)"

#: units of the slip table's columns (those not in the run file's own documentation)
SLIP_UNITS = dict(ANALYSIS_UNITS, **{k: v[0] for k, v in SLIP_ATTRS.items()},
                  peak_velocity_over_Vs="-", mean_velocity_over_Vs="-", fit_amplitude="v0", fit_half_period="t0",
                  fit_r2="-", fit_ok="-", fit_verdict="-", fit_reason="-", m_eff="rho_s d^2", m_eff_over_m_b="-",
                  checkpoint_path="-")


class SeriesArray(BackendArray):
    """One /series column as a lazily indexed array: each read opens the file for that slice only."""

    def __init__(self, h5_path: Path, name: str, n: int):
        self.h5_path, self.name = h5_path, name
        self.shape = (n,)
        self.dtype = np.dtype("float64")

    def __getitem__(self, key):
        return indexing.explicit_indexing_adapter(key, self.shape, indexing.IndexingSupport.BASIC, self._read)

    def _read(self, key):
        return np.asarray(read_series_items(self.h5_path, self.name, key), dtype=np.float64)


def var_attrs(unit: str, description: str, name: str | None = None) -> dict:
    """xarray attributes: units, a short ``long_name`` for plot labels (``name`` in words, or the
    description up to its first comma or parenthesis, at most 40 characters) and the whole sentence
    as ``description``."""
    short = name.replace("_", " ") if name else re.split(r"[,(;]", description, maxsplit=1)[0].strip()
    return {"units": pint_unit(unit), "long_name": short if len(short) <= 40 else short[:39] + "…",
            "description": description}


def to_si(obj, scales: dict, V_s: float = _NAN, sigma: float = _NAN, m_b: float = _NAN):
    """A copy of ``obj`` in SI units: an xarray DataArray or Dataset (each variable and coordinate by
    its ``units`` attribute) or a pandas DataFrame (each column by ``df.attrs["units"]``). Values in
    units made of the scales (d_grain, E, t0, v0, rho_s; V_s, sigma_n and m_b of the run) are multiplied by their
    SI size and their unit becomes the SI one ('E d^3' -> 'Pa * m**3'); the rest is left as it is.
    ``scales``: :attr:`Run.scales`. :meth:`Run.to_si` and :meth:`Pair.to_si` fill in the run's."""
    sizes = unit_sizes(scales, V_s, sigma, m_b)

    def convert(unit, kind: str):
        si = si_of(str(unit), sizes) if unit is not None and kind in "iuf" else None
        return None if si is None or si[1] == "1" else si

    if isinstance(obj, pd.DataFrame):
        out = obj.copy()
        units = dict(obj.attrs.get("units", {}))
        for column in out.columns:
            si = convert(units.get(column), out[column].dtype.kind)
            if si is not None:
                out[column] = out[column] * si[0]
                units[column] = si[1]
        out.attrs["units"] = units
        return out
    if isinstance(obj, xr.DataArray):
        name = obj.name if obj.name is not None else "_value"
        out = to_si(obj.to_dataset(name=name) if name not in obj.coords else obj.coords.to_dataset(), scales, V_s,
                    sigma, m_b)
        return out[name].rename(obj.name)
    if isinstance(obj, xr.Dataset):
        out = obj.copy()
        for name in list(out.variables):
            var = out.variables[name]
            si = convert(var.attrs.get("units"), var.dtype.kind)
            if si is None:
                continue
            new = (var.dims, var.values * si[0], dict(var.attrs, units=si[1]))
            if name in out.coords:
                out = out.assign_coords({name: new})
            else:
                out[name] = new
        return out
    raise TypeError(f"to_si takes an xarray DataArray or Dataset or a pandas DataFrame, not {type(obj).__name__}")


def pair_frame(rows: list[dict], extra: tuple = ()) -> pd.DataFrame:
    """Pair rows (PAIR_COLUMNS, after the ``extra`` columns) as a DataFrame with ``attrs["units"]``."""
    df = pd.DataFrame(rows, columns=list(extra) + list(PAIR_COLUMNS))
    df.attrs["units"] = {c: pint_unit(PAIR_UNITS.get(c, "-")) for c in df.columns}
    df.attrs["units"].update({c: pint_unit(u) for c, u in dict(k="E/d", V_s="v0", sigma="E").items()})
    return df
