"""`gouge export`: a run or fork branch as one time-dependent VTKHDF file for ParaView.

Layout: a VTKHDF ``PartitionedDataSetCollection`` (format 2.2) with one temporal ``PolyData``
block per kind of object, every block with the same ``Steps/Values`` (the snapshot times in
t0 since loading began, the time origin of every gouge command)::

    /VTKHDF                 Type PartitionedDataSetCollection; Assembly/<block> -> links
    /VTKHDF/grains          one vertex per grain, point index = original grain number
                            point data: grain_id, radius [d], velocity [v0] (3), spin [1/t0],
                            body (0 free, 1 bottom wall, 2 top wall), contact_count,
                            contact_force [E d^2] (3, net elastic contact force),
                            contact_force_sum [E d^2] (sum of contact force magnitudes)
    /VTKHDF/contacts        one line per touching pair, from grain i to the nearest periodic
                            image of grain j; cell data: normal_force [E d^2] (> 0 compressive),
                            tangential_force [E d^2] (signed, along n rotated +90 degrees),
                            force [E d^2] (3, on j by i), grain_i, grain_j
    /VTKHDF/walls           two lines across the width at the wall planes (mean z of the
                            wall grains); cell data: wall (1 bottom, 2 top), velocity [v0] (3)
    /VTKHDF/pressure_grid   (fluid only) one quad per pressure cell at its true position in that
                            snapshot; cell data: pressure [E], pressure_over_sigma [-], porosity [-]
    /gouge                  attrs: units, time_origin, axes, source run file (outside /VTKHDF,
                            ignored by VTK)

Coordinates: VTK (x, y, z) = (x along the fault, z across the layer, 0), so ParaView shows the
layer face-on; grains are wrapped into [0, width). Why a collection of PolyData and not an
ImageData grid: the pressure grid stretches with the layer (its z origin and spacing change
from snapshot to snapshot), while a temporal VTKHDF ImageData has one origin and spacing for
all steps; the quads carry the true geometry of each step, and the per-step origin and spacing
are also the ``origin``/``spacing`` attributes of the run file's pressure datasets.

With ``split`` each block is written as its own temporal PolyData file instead (same arrays and
steps), for readers without temporal collections. Checked with VTK 9.7's vtkHDFReader: the
collection's time steps are served to a pipeline (ParaView's time slider) and by ``SetStep``;
a time request made after an explicit ``UpdateInformation`` on the reader itself returns step 0
for temporal collections (also for files written by VTK's own vtkHDFWriter), not for PolyData.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from ..driver.progress import ItemProgress
from ..errors import ExportError
from ..io.outputs import check_out, write_bytes
from ..io.runreader import RunReader
from ..io.filedoc import BODY_CODES, TIME_ORIGIN

VERSION = (2, 2)
TOPOLOGIES = ("Vertices", "Lines", "Polygons", "Strips")


@dataclass
class Piece:
    """One time step of one PolyData block: points (P, 3); cells of one topology given as
    offsets (C + 1,) and connectivity; point and cell data arrays with P resp. C rows."""

    points: np.ndarray
    topology: str
    offsets: np.ndarray
    connectivity: np.ndarray
    point_data: dict = field(default_factory=dict)
    cell_data: dict = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        return int(self.offsets.size - 1)


def _xyz(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    return np.column_stack([x, z, np.zeros_like(x)])


def _vec(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.column_stack([a, b, np.zeros_like(a)])


def contact_geometry(snap: dict, width: float) -> dict:
    """Per contact: unit normal n from i to the nearest image of j (m, 2), the j image's x,
    normal force F.n (> 0 compressive) and tangential force F.t, t = n rotated by +90 degrees."""
    ci, cj = snap["contact_i"].astype(np.int64), snap["contact_j"].astype(np.int64)
    x, z = np.mod(snap["x"], width), snap["z"]
    dx = x[cj] - x[ci]
    dx -= width * np.round(dx / width)
    dz = z[cj] - z[ci]
    dist = np.hypot(dx, dz)
    dist[dist == 0] = 1.0
    nx, nz = dx / dist, dz / dist
    fx, fz = snap["contact_fx"], snap["contact_fz"]
    return {"i": ci, "j": cj, "xi": x[ci], "zi": z[ci], "xj": x[ci] + dx, "zj": z[ci] + dz,
            "normal": fx * nx + fz * nz, "tangential": -fx * nz + fz * nx}


def grains_piece(snap: dict, width: float) -> Piece:
    n = snap["x"].size
    count = np.zeros(n, np.int32)
    fx, fz, fsum = np.zeros(n), np.zeros(n), np.zeros(n)
    if snap.get("contact_i") is not None and snap["contact_i"].size:
        ci, cj = snap["contact_i"].astype(np.int64), snap["contact_j"].astype(np.int64)
        cfx, cfz = snap["contact_fx"], snap["contact_fz"]
        mag = np.hypot(cfx, cfz)
        np.add.at(count, ci, 1)
        np.add.at(count, cj, 1)
        np.add.at(fx, cj, cfx)         # the stored force acts on j; i gets the opposite
        np.add.at(fz, cj, cfz)
        np.add.at(fx, ci, -cfx)
        np.add.at(fz, ci, -cfz)
        np.add.at(fsum, ci, mag)
        np.add.at(fsum, cj, mag)
    return Piece(
        points=_xyz(np.mod(snap["x"], width), snap["z"]), topology="Vertices",
        offsets=np.arange(n + 1, dtype=np.int64), connectivity=np.arange(n, dtype=np.int64),
        point_data={"grain_id": np.arange(n, dtype=np.int64), "radius": snap["radius"],
                    "velocity": _vec(snap["vx"], snap["vz"]), "spin": snap["spin"],
                    "body": snap["body"].astype(np.int32), "contact_count": count,
                    "contact_force": _vec(fx, fz), "contact_force_sum": fsum})


def contacts_piece(snap: dict, width: float) -> Piece:
    if snap.get("contact_i") is None:
        snap = dict(snap, contact_i=np.zeros(0, np.int64), contact_j=np.zeros(0, np.int64),
                    contact_fx=np.zeros(0), contact_fz=np.zeros(0))
    m = int(snap["contact_i"].size)
    g = contact_geometry(snap, width)
    points = np.empty((2 * m, 3))
    points[0::2] = _xyz(g["xi"], g["zi"])
    points[1::2] = _xyz(g["xj"], g["zj"])
    return Piece(points, "Lines", np.arange(0, 2 * m + 1, 2, dtype=np.int64), np.arange(2 * m, dtype=np.int64),
                 cell_data={"normal_force": g["normal"], "tangential_force": g["tangential"],
                            "force": _vec(snap["contact_fx"], snap["contact_fz"]),
                            "grain_i": g["i"], "grain_j": g["j"]})


def wall_planes(snap: dict) -> tuple[float, float]:
    """(z_bottom, z_top): mean z of the bottom- and top-wall grains [d]."""
    body, z = snap["body"], snap["z"]
    return float(z[body == 1].mean()), float(z[body == 2].mean())


def walls_piece(snap: dict, width: float) -> Piece:
    zb, zt = wall_planes(snap)
    body = snap["body"]
    vel = np.array([[snap["vx"][body == b].mean(), snap["vz"][body == b].mean(), 0.0] for b in (1, 2)])
    points = np.array([[0.0, zb, 0.0], [width, zb, 0.0], [0.0, zt, 0.0], [width, zt, 0.0]])
    return Piece(points, "Lines", np.array([0, 2, 4], np.int64), np.arange(4, dtype=np.int64),
                 cell_data={"wall": np.array([1, 2], np.int32), "velocity": vel})


def grid_geometry_of(snap: dict, attrs: dict, width: float) -> tuple[np.ndarray, np.ndarray]:
    """(origin [x, z], spacing [dx, dz]) of the snapshot's pressure grid [d]: the stored
    attributes, or for files written before they existed, the wall planes."""
    nx, nz = snap["pressure"].shape
    if "origin" in attrs and "spacing" in attrs:
        return np.asarray(attrs["origin"], float), np.asarray(attrs["spacing"], float)
    zb, zt = wall_planes(snap)
    return np.array([0.0, zb]), np.array([width / nx, (zt - zb) / nz])


def grid_piece(snap: dict, attrs: dict, width: float, sigma: float) -> Piece:
    p = np.asarray(snap["pressure"], float)
    nx, nz = p.shape
    origin, spacing = grid_geometry_of(snap, attrs, width)
    xs = origin[0] + spacing[0] * np.arange(nx + 1)
    zs = origin[1] + spacing[1] * np.arange(nz + 1)
    X, Z = np.meshgrid(xs, zs, indexing="ij")                  # point (i, j) -> i * (nz + 1) + j
    points = _xyz(X.ravel(), Z.ravel())
    i, j = np.meshgrid(np.arange(nx), np.arange(nz), indexing="ij")   # cell (i, j) -> i * nz + j
    a = (i * (nz + 1) + j).ravel()
    quads = np.column_stack([a, a + nz + 1, a + nz + 2, a + 1]).ravel().astype(np.int64)
    cells = {"pressure": p.ravel(), "pressure_over_sigma": p.ravel() / sigma}
    if snap.get("porosity") is not None:
        cells["porosity"] = np.asarray(snap["porosity"], float).ravel()
    return Piece(points, "Polygons", np.arange(0, 4 * nx * nz + 1, 4, dtype=np.int64), quads, cell_data=cells)


def _empty_like(piece: Piece) -> Piece:
    def empty(a):
        return np.zeros((0,) + a.shape[1:], a.dtype)

    return Piece(np.zeros((0, 3)), piece.topology, np.zeros(1, np.int64), np.zeros(0, np.int64),
                 {k: empty(v) for k, v in piece.point_data.items()}, {k: empty(v) for k, v in piece.cell_data.items()})


def _put(group: h5py.Group, name: str, data: np.ndarray) -> None:
    """A dataset, gzip-compressed when it is large (the reader decompresses chunked datasets)."""
    data = np.asarray(data)
    big = data.size > 4096
    group.create_dataset(name, data=data, compression="gzip" if big else None, compression_opts=4 if big else None,
                         shuffle=big)


def write_block(group: h5py.Group, pieces: list[Piece], times: np.ndarray) -> None:
    """A temporal VTKHDF PolyData in ``group``: one piece (one partition) per time step,
    arrays concatenated over the steps and addressed through ``Steps``."""
    group.attrs["Version"] = VERSION
    group.attrs.create("Type", np.bytes_("PolyData"))
    n = len(pieces)
    npts = np.array([p.points.shape[0] for p in pieces], np.int64)
    group.create_dataset("NumberOfPoints", data=npts)
    _put(group, "Points", np.concatenate([p.points for p in pieces]).astype(float))
    cells = np.zeros((n, 4), np.int64)
    conn = np.zeros((n, 4), np.int64)
    for k, topo in enumerate(TOPOLOGIES):
        ncell = np.array([p.n_cells if p.topology == topo else 0 for p in pieces], np.int64)
        nconn = np.array([p.connectivity.size if p.topology == topo else 0 for p in pieces], np.int64)
        cells[:, k], conn[:, k] = ncell, nconn
        g = group.create_group(topo, track_order=True)
        g.create_dataset("NumberOfCells", data=ncell)
        g.create_dataset("NumberOfConnectivityIds", data=nconn)
        _put(g, "Offsets", np.concatenate(
            [p.offsets if p.topology == topo else np.zeros(1, np.int64) for p in pieces]).astype(np.int64))
        _put(g, "Connectivity", np.concatenate(
            [p.connectivity if p.topology == topo else np.zeros(0, np.int64) for p in pieces]).astype(np.int64))
    for kind, attr in (("PointData", "point_data"), ("CellData", "cell_data")):
        g = group.create_group(kind, track_order=True)
        for name in getattr(pieces[0], attr):
            _put(g, name, np.concatenate([getattr(p, attr)[name] for p in pieces]))
    steps = group.create_group("Steps", track_order=True)
    steps.attrs["NSteps"] = n
    steps.create_dataset("Values", data=np.asarray(times, float))
    steps.create_dataset("PartOffsets", data=np.arange(n, dtype=np.int64))
    steps.create_dataset("NumberOfParts", data=np.ones(n, np.int64))
    point_offsets = np.concatenate([[0], np.cumsum(npts)[:-1]]).astype(np.int64)
    steps.create_dataset("PointOffsets", data=point_offsets)
    steps.create_dataset("CellOffsets", data=np.vstack([np.zeros((1, 4), np.int64), np.cumsum(cells, 0)[:-1]]))
    steps.create_dataset("ConnectivityIdOffsets", data=np.vstack([np.zeros((1, 4), np.int64),
                                                                  np.cumsum(conn, 0)[:-1]]))
    total_cells = cells.sum(1)
    cell_offsets = np.concatenate([[0], np.cumsum(total_cells)[:-1]]).astype(np.int64)
    for kind, attr, offsets in (("PointDataOffsets", "point_data", point_offsets),
                                ("CellDataOffsets", "cell_data", cell_offsets)):
        g = steps.create_group(kind, track_order=True)
        for name in getattr(pieces[0], attr):
            g.create_dataset(name, data=offsets)


@dataclass
class ExportResult:
    path: Path
    times: np.ndarray
    blocks: dict          # block name -> number of points in the last step
    source: Path
    paths: list           # every file written (one, or one per block with split)


def default_export_path(info) -> Path:
    """``RUN/export/<run>.vtkhdf``, for a fork ``PARENT/export/slip_NNN_<branch>.vtkhdf``: the parent
    found from the branch folder (:attr:`RunInfo.parent_dir`), never from the current directory.
    Raises :class:`ExportError` if the path would leave the run directory."""
    if info.is_fork:
        root = info.parent_dir
        out = root / "export" / f"slip_{info.fork_slip:03d}_{info.branch}.vtkhdf"
    else:
        root = info.run_dir
        out = root / "export" / f"{info.run_dir.name}.vtkhdf"
    if not out.resolve().is_relative_to(root.resolve()):
        raise ExportError(f"the default export path {out} lies outside the run {root}; give --out")
    return out


def is_export(path: Path) -> bool:
    """Whether `path` is a file `gouge export` wrote (HDF5 with /VTKHDF and /gouge's source)."""
    try:
        with h5py.File(path, "r") as h5:
            return "VTKHDF" in h5 and "gouge" in h5 and "source" in h5["gouge"].attrs
    except (OSError, KeyError, RuntimeError):
        return False


def export_run(run_dir: Path | str, out: Path | str | None = None, split: bool = False,
               progress: bool = True, force: bool = False, command: str | None = None) -> ExportResult:
    """Write every snapshot of a run (or fork branch) directory to ``out`` (default
    ``RUN/export/<run or branch>.vtkhdf``, for a fork ``PARENT/export/slip_NNN_<branch>.vtkhdf``).
    ``split``: one temporal PolyData file per block instead (``<out stem>_<block>.vtkhdf``), for
    readers without temporal collections. ``progress``: a plain line on stderr every few seconds.
    An existing ``out`` is replaced only if it is an export and ``force`` is given (or it is the
    default path); each file is built in memory, checked against the free space and written
    through a temporary file (:mod:`gouge_cli.io.outputs`); ``command``: what a full disk names
    to continue."""
    default = out is None
    if out is not None:
        for path in _out_paths(Path(out), split):
            check_out(path, is_export, "a VTKHDF export", force)
    with RunReader(run_dir) as reader:
        info = reader.info
        names = reader.snapshot_names()
        if not names:
            raise ExportError(f"{info.describe()} has no snapshots to export; set output.snapshot_interval "
                              "(forks: output.dense_snapshots) so that the run writes some")
        offset = reader.time_offset()
        blocks: dict[str, list[Piece]] = {"grains": [], "contacts": [], "walls": [], "pressure_grid": []}
        times = []
        ticker = ItemProgress(f"export {info.run_dir.name}: snapshots", len(names), quiet=not progress)
        for done, name in enumerate(names):
            ticker.update(done)
            snap = reader.snapshot(name)
            attrs = dict(reader.h5["snapshots"][name].attrs)
            pattrs = dict(reader.h5["snapshots"][name]["pressure"].attrs) if "pressure" in snap else {}
            times.append(float(attrs["load_time"]) if "load_time" in attrs else snap["time"] - offset)
            blocks["grains"].append(grains_piece(snap, info.width))
            blocks["contacts"].append(contacts_piece(snap, info.width))
            blocks["walls"].append(walls_piece(snap, info.width))
            blocks["pressure_grid"].append(grid_piece(snap, pattrs, info.width, info.sigma)
                                           if "pressure" in snap else None)
        grid = blocks.pop("pressure_grid")
        if any(p is not None for p in grid):
            model = next(p for p in grid if p is not None)
            blocks["pressure_grid"] = [p if p is not None else _empty_like(model) for p in grid]
        if out is None:
            out = default_export_path(info)
        source = info.h5_path
    out = Path(out)
    if default:
        for path in _out_paths(out, split):
            check_out(path, is_export, "a VTKHDF export", force, default=True)
    next_step = f"run `{command or f'gouge export {run_dir}'}` again"
    out.parent.mkdir(parents=True, exist_ok=True)
    times = np.asarray(times)
    last = {k: int(v[-1].points.shape[0]) for k, v in blocks.items()}
    if split:
        paths = []
        for name, pieces in blocks.items():
            path = out.with_name(f"{out.stem}_{name}.vtkhdf")
            _atomic(path, lambda h5, pieces=pieces: write_block(h5.create_group("VTKHDF", track_order=True),
                                                                pieces, times), info, source, next_step)
            paths.append(path)
        return ExportResult(paths[0], times, last, source, paths)

    def collection(h5):
        root = h5.create_group("VTKHDF", track_order=True)
        root.attrs["Version"] = VERSION
        root.attrs.create("Type", np.bytes_("PartitionedDataSetCollection"))
        assembly = root.create_group("Assembly", track_order=True)
        for index, (name, pieces) in enumerate(blocks.items()):
            block = root.create_group(name, track_order=True)
            write_block(block, pieces, times)
            block.attrs["Index"] = index
            assembly[name] = h5py.SoftLink(f"/VTKHDF/{name}")

    _atomic(out, collection, info, source, next_step)
    return ExportResult(out, times, last, source, [out])


def _out_paths(out: Path, split: bool) -> list[Path]:
    if not split:
        return [out]
    return [out.with_name(f"{out.stem}_{name}.vtkhdf") for name in ("grains", "contacts", "walls", "pressure_grid")]


def _atomic(path: Path, fill, info, source: Path, next_step: str) -> None:
    """Build ``fill(h5)`` plus the /gouge metadata group in memory, then write it whole through a
    temporary file (HDF5 never meets a full disk, so no half-closed file can crash)."""
    image = io.BytesIO()
    with h5py.File(image, "w", track_order=True) as h5:
        fill(h5)
        meta = h5.create_group("gouge", track_order=True)
        meta.attrs["source"] = str(source)
        meta.attrs["time_origin"] = TIME_ORIGIN
        meta.attrs["axes"] = "VTK x = x along the fault (wrapped into [0, width)), VTK y = z across the layer"
        meta.attrs["units"] = ("dimensionless: length d, stress E, time t0, velocity v0 = d/t0, force E d^2 "
                               "(per unit out-of-plane thickness d); SI sizes in the run file's scales")
        meta.attrs["body_codes"] = json.dumps(BODY_CODES)
        meta.attrs["width"] = info.width
        meta.attrs["sigma"] = info.sigma
    write_bytes(path, image.getbuffer(), next_step)
