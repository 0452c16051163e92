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


def snapshot_figure(snap: dict, width: float, path: Path, title: str = "", sigma: float | None = None,
                    time_offset: float = 0.0) -> Path:
    """Draw one snapshot (dict of arrays from :meth:`RunReader.snapshot`) to ``path``.

    ``sigma`` scales the pressure to P/sigma (else P in E). Returns the path; the pixel size
    is ``snapshot_figsize(...) * DPI``.
    """
    x, z, r, body = snap["x"], snap["z"], snap["radius"], snap["body"].astype(int)
    x = np.mod(x, width)
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
        p = np.asarray(pressure, float)
        scale = sigma if sigma else 1.0
        p = p / scale
        nx, nz = p.shape
        zb, zt = _wall_planes(snap)
        xe = np.linspace(0.0, width, nx + 1)
        ze = np.linspace(zb, zt, nz + 1)
        vmax = float(np.nanmax(np.abs(p))) or 1e-12
        mesh = ax.pcolormesh(xe, ze, p.T, cmap="RdBu_r", norm=TwoSlopeNorm(0.0, -vmax, vmax),
                             shading="flat", zorder=0)
        cax = fig.add_axes([1 - right + 0.25 / w_in, bottom, 0.22 / w_in, 1 - bottom - top])
        cb = fig.colorbar(mesh, cax=cax)
        cb.set_label(LABEL["pressure"] if sigma else "P / E", fontsize=9)
        cb.ax.tick_params(labelsize=8)
        ax.axhline(zb, color="0.3", lw=0.5, ls="--", zorder=1)
        ax.axhline(zt, color="0.3", lw=0.5, ls="--", zorder=1)

    # discs, with periodic images of those touching a side
    near_left = x < r
    near_right = x > width - r
    xs = np.concatenate([x, x[near_left] + width, x[near_right] - width])
    zs = np.concatenate([z, z[near_left], z[near_right]])
    rs = np.concatenate([r, r[near_left], r[near_right]])
    bs = np.concatenate([body, body[near_left], body[near_right]])
    face = np.empty((bs.size, 4))
    free_rgba = plt.matplotlib.colors.to_rgba(FREE_FACE, 0.25 if has_p else 1.0)
    face[:] = free_rgba
    face[bs == 1] = plt.matplotlib.colors.to_rgba(BOTTOM_WALL)
    face[bs == 2] = plt.matplotlib.colors.to_rgba(TOP_WALL)
    discs = EllipseCollection(2 * rs, 2 * rs, np.zeros_like(rs), units="xy", offsets=np.column_stack([xs, zs]),
                              offset_transform=ax.transData, facecolors=face,
                              edgecolors=FREE_EDGE, linewidths=0.3, zorder=2)
    ax.add_collection(discs)

    # force chains
    ci, cj = snap.get("contact_i"), snap.get("contact_j")
    n_contacts = 0 if ci is None else int(np.size(ci))
    if n_contacts:
        f = np.hypot(snap["contact_fx"], snap["contact_fz"])
        fmax = float(f.max()) or 1.0
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
        segments = np.concatenate(seg)
        force = np.concatenate(weights)
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


__all__ = ["snapshot_figure", "snapshot_figsize", "snapshot_pixels"]
