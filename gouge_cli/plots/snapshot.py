"""Grain snapshot: discs, contact-force chains and the pore-pressure field (thesis Figs. 2, 16).

Discs are one EllipseCollection, chains one LineCollection (width proportional to the
contact force), the pressure a pcolormesh of the cell-centred grid between the wall
planes, so a 10k-grain snapshot draws in a few seconds. x is periodic on [0, width):
grains touching a side are drawn again one width over, and a contact whose centres
are more than width/2 apart is drawn as its two wrapped halves; the axes clip both.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.colors import TwoSlopeNorm
from matplotlib.patches import Patch

from .style import DPI, LABEL, save

FREE_FACE = "#d9d9d9"
FREE_EDGE = "#7f7f7f"
BOTTOM_WALL = "#4d4d4d"
TOP_WALL = "#b8860b"
CHAIN = "#111111"
WIDE_IN = 10.0       # the longer side of the layer spans at least this many inches,
INCH_PER_D = 0.1     # or this many per grain diameter for big layers,
MAX_IN = 24.0        # but at most this many


def _extent(snap: dict, width: float) -> tuple[float, float]:
    r = snap["radius"]
    return float(np.min(snap["z"] - r)), float(np.max(snap["z"] + r))


def snapshot_figsize(width: float, z_min: float, z_max: float, pressure: bool) -> tuple[float, float]:
    """Figure size [in] for a layer ``width`` wide spanning ``[z_min, z_max]``: the longer side of the
    layer gets ``INCH_PER_D`` inches per d, clamped to [WIDE_IN, MAX_IN], plus room for labels,
    legend and colorbar; rounded to whole pixels."""
    height = max(z_max - z_min, 1e-9)
    aspect = height / width
    long_in = min(max(WIDE_IN, INCH_PER_D * max(width, height)), MAX_IN)
    if aspect <= 1.0:
        w_ax, h_ax = long_in, max(long_in * aspect, 1.5)
    else:
        w_ax, h_ax = max(long_in / aspect, 2.5), long_in
    extra_w = 2.3 if pressure else 1.0
    w = max(w_ax + extra_w, 5.0)
    h = h_ax + 1.6
    return round(w * DPI) / DPI, round(h * DPI) / DPI     # whole pixels


def _wall_planes(snap: dict) -> tuple[float, float]:
    body, z = snap["body"], snap["z"]
    bottom = z[body == 1]
    top = z[body == 2]
    zb = float(bottom.mean()) if bottom.size else float(z.min())
    zt = float(top.mean()) if top.size else float(z.max())
    return zb, zt


def pressure_grid(snap: dict, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell edges (xe (nx+1,), ze (nz+1,)) of the snapshot's pressure grid [d]: from the stored
    origin/spacing (``snap['grid']``, see :meth:`RunReader.snapshot`), else the wall planes."""
    nx, nz = np.shape(snap["pressure"])
    grid = snap.get("grid")
    if grid is not None:
        (x0, z0), (dx, dz) = grid["origin"], grid["spacing"]
        return x0 + dx * np.arange(nx + 1), z0 + dz * np.arange(nz + 1)
    zb, zt = _wall_planes(snap)
    return np.linspace(0.0, width, nx + 1), np.linspace(zb, zt, nz + 1)


def draw_pressure(ax, snap: dict, width: float, scale: float, vmax: float):
    """Pore pressure P/scale as a cell mesh with a symmetric colour scale [-vmax, vmax]; returns it."""
    xe, ze = pressure_grid(snap, width)
    p = np.asarray(snap["pressure"], float) / scale
    return ax.pcolormesh(xe, ze, p.T, cmap="RdBu_r", norm=TwoSlopeNorm(0.0, -vmax, vmax), shading="flat", zorder=0)


def draw_discs(ax, snap: dict, width: float, free_alpha: float = 1.0):
    """Grains as discs (wall grains coloured), with periodic images of those touching a side."""
    x, z, r, body = np.mod(snap["x"], width), snap["z"], snap["radius"], snap["body"].astype(int)
    near_left = x < r
    near_right = x > width - r
    xs = np.concatenate([x, x[near_left] + width, x[near_right] - width])
    zs = np.concatenate([z, z[near_left], z[near_right]])
    rs = np.concatenate([r, r[near_left], r[near_right]])
    bs = np.concatenate([body, body[near_left], body[near_right]])
    face = np.empty((bs.size, 4))
    face[:] = plt.matplotlib.colors.to_rgba(FREE_FACE, free_alpha)
    face[bs == 1] = plt.matplotlib.colors.to_rgba(BOTTOM_WALL)
    face[bs == 2] = plt.matplotlib.colors.to_rgba(TOP_WALL)
    discs = EllipseCollection(2 * rs, 2 * rs, np.zeros_like(rs), units="xy", offsets=np.column_stack([xs, zs]),
                              offset_transform=ax.transData, facecolors=face,
                              edgecolors=FREE_EDGE, linewidths=0.3, zorder=2)
    ax.add_collection(discs)


def chain_segments(snap: dict, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Force-chain segments (m', 2, 2) between contacting centres and their force magnitudes
    (m',) [E d^2]; a contact across the periodic side is drawn as its two wrapped halves."""
    ci, cj = snap.get("contact_i"), snap.get("contact_j")
    if ci is None or np.size(ci) == 0:
        return np.zeros((0, 2, 2)), np.zeros(0)
    x, z = np.mod(snap["x"], width), snap["z"]
    f = np.hypot(snap["contact_fx"], snap["contact_fz"])
    xi, zi, xj, zj = x[ci], z[ci], x[cj], z[cj]
    dx = xj - xi
    shift = -width * np.round(dx / width)
    wrapped = shift != 0
    seg = [np.stack([np.column_stack([xi, zi]), np.column_stack([xi + dx + shift, zj])], axis=1)]
    weights = [f]
    if np.any(wrapped):   # the other half of a contact across the periodic side
        w = wrapped
        seg.append(np.stack([np.column_stack([xj[w], zj[w]]),
                             np.column_stack([xj[w] - dx[w] - shift[w], zi[w]])], axis=1))
        weights.append(f[w])
    return np.concatenate(seg), np.concatenate(weights)


def snapshot_figure(snap: dict, width: float, path: Path, title: str = "", sigma: float | None = None,
                    time_offset: float = 0.0) -> Path:
    """Draw one snapshot (dict of arrays from :meth:`RunReader.snapshot`) to ``path``.

    ``sigma`` scales the pressure to P/sigma (else P in E). Returns the path; the pixel size
    is ``snapshot_figsize(...) * DPI``.
    """
    x, r = snap["x"], snap["radius"]
    z_min, z_max = _extent(snap, width)
    pressure = snap.get("pressure")
    has_p = pressure is not None and np.size(pressure) > 0
    figsize = snapshot_figsize(width, z_min, z_max, has_p)
    fig = plt.figure(figsize=figsize, dpi=DPI)
    w_in, h_in = figsize
    left, right = 0.75 / w_in, (1.45 if has_p else 0.25) / w_in
    bottom, top = 0.6 / h_in, 1.0 / h_in
    ax = fig.add_axes([left, bottom, 1 - left - right, 1 - bottom - top])
    ax.set_xlim(0.0, width)
    ax.set_ylim(z_min, z_max)
    ax.set_aspect("equal", adjustable="box")
    ax.set_facecolor("white")

    # pressure field underneath
    if has_p:
        scale = sigma if sigma else 1.0
        vmax = float(np.nanmax(np.abs(np.asarray(pressure, float) / scale))) or 1e-12
        mesh = draw_pressure(ax, snap, width, scale, vmax)
        cax = fig.add_axes([1 - right + 0.25 / w_in, bottom, 0.22 / w_in, 1 - bottom - top])
        cb = fig.colorbar(mesh, cax=cax)
        cb.set_label(LABEL["pressure"] if sigma else "P / E", fontsize=9)
        cb.ax.tick_params(labelsize=8)
        _, ze = pressure_grid(snap, width)
        for zp in (ze[0], ze[-1]):
            ax.axhline(zp, color="0.3", lw=0.5, ls="--", zorder=1)

    draw_discs(ax, snap, width, 0.25 if has_p else 1.0)

    # force chains
    segments, force = chain_segments(snap, width)
    n_contacts = 0 if snap.get("contact_i") is None else int(np.size(snap["contact_i"]))
    if n_contacts:
        fmax = float(force.max()) or 1.0
        # widest line about 0.6 grain diameter at the figure scale, at most 4 pt
        box_w, box_h = (1 - left - right) * w_in, (1 - bottom - top) * h_in
        pt_per_d = 72.0 * min(box_w / width, box_h / (z_max - z_min))
        d_mean = 2.0 * float(np.mean(r))
        lw_max = min(4.0, max(0.8, 0.6 * d_mean * pt_per_d))
        keep = force > 0.02 * fmax
        chains = LineCollection(segments[keep], linewidths=0.15 + lw_max * force[keep] / fmax,
                                colors=CHAIN, capstyle="round", zorder=3)
        ax.add_collection(chains)

    ax.set_xlabel(LABEL["x"])
    ax.set_ylabel(LABEL["z"])
    handles = [Patch(facecolor=FREE_FACE, edgecolor=FREE_EDGE, label="free grain"),
               Patch(facecolor=BOTTOM_WALL, label="bottom wall (fixed)"),
               Patch(facecolor=TOP_WALL, label="top wall (spring-driven)"),
               plt.Line2D([], [], color=CHAIN, lw=2, label="contact force ∝ width")]
    fig.legend(handles=handles, loc="upper center", ncol=4, fontsize=8, frameon=False,
               bbox_to_anchor=(0.5, 1 - 0.45 / h_in))
    t = snap["time"] - time_offset
    head = title or "snapshot"
    p_note = ""
    if has_p:
        p_note = f", max |P|/{'σ' if sigma else 'E'} = {vmax:.3g}"
    fig.suptitle(f"{head}: t = {t:.6g} t₀ (step {snap['step']}), {x.size} grains, {n_contacts} contacts{p_note}",
                 fontsize=10, y=1 - 0.12 / h_in, va="top")
    return save(fig, path)


def snapshot_pixels(width: float, snap: dict) -> tuple[int, int]:
    """(width, height) in pixels of :func:`snapshot_figure` for this snapshot."""
    z_min, z_max = _extent(snap, width)
    w, h = snapshot_figsize(width, z_min, z_max, snap.get("pressure") is not None)
    return int(round(w * DPI)), int(round(h * DPI))


__all__ = ["chain_segments", "draw_discs", "draw_pressure", "pressure_grid", "snapshot_figure", "snapshot_figsize",
           "snapshot_pixels"]
