"""`gouge movie`: one slip, drained and undrained side by side from the same packing.

Frames are the branches' snapshots (forks write ``output.slip_frames`` of them per predicted
slip duration while the wall slips), aligned on time since each branch's own slip onset
tau = t - t_onset: frame k shows each branch at its snapshot nearest tau_k. Each panel: pore
pressure P/sigma shaded on one fixed colour scale for the whole movie (the largest |P|/sigma
of the undrained frames), grains, force chains with line width proportional to the contact
force (``FORCE_SCALE_PT`` points for a force sigma d, i.e. the normal stress on one grain
diameter, capped at ``MAX_LINE_PT``), the time since onset; below, v_w/V_s of both branches
against tau with a marker at the frame's time.

Encoding: MP4 (H.264) through the ffmpeg binary shipped by the ``imageio-ffmpeg`` package;
without it, an animated GIF (Pillow, which matplotlib needs anyway).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from ..analysis.catalog import find_slip, read_catalog
from ..analysis.forkpairs import fork_branches
from ..io.layout import RunLayout, branch_name, branch_perm, perm_text
from ..driver.progress import ItemProgress
from ..errors import MovieError
from ..io.outputs import check_out, require_space, temporary
from ..io.runreader import RunReader
from .snapshot import CHAIN, chain_segments, draw_discs, draw_pressure, pressure_grid
from .style import DRAINED, LABEL, UNDRAINED

FRAME_PX = (1280, 720)          # even sizes (H.264 with yuv420p needs them)
MOVIE_DPI = 100
FORCE_SCALE_PT = 0.6            # line width [pt] of a contact carrying sigma * d
MAX_LINE_PT = 5.0
MIN_FORCE_FRACTION = 0.25       # chains below a quarter of sigma d are not drawn
FPS = 12


@dataclass
class Branch:
    """One branch of the fork: reader, its onset [t0 clock], snapshot names and tau of each."""

    label: str
    reader: RunReader
    onset: float
    names: list
    tau: np.ndarray
    series_tau: np.ndarray
    series_v: np.ndarray

    def nearest(self, tau: float) -> str:
        return self.names[int(np.argmin(np.abs(self.tau - tau)))]


def _branch(label: str, run_dir: Path) -> Branch:
    reader = RunReader(run_dir)
    names = reader.snapshot_names()
    if not names:
        reader.close()
        raise MovieError(f"{run_dir} has no snapshots; run the fork again (`gouge restart ... --force`), "
                         "it writes output.slip_frames of them per slip duration")
    catalog = read_catalog(reader)
    s = reader.series(["time", "wall_vx"])
    onset = catalog[0].onset_time if catalog else float(s["time"][int(np.argmax(s["wall_vx"]))])
    tau = np.array(reader.snapshot_times()) - onset
    return Branch(label, reader, onset, names, tau, s["time"] - onset, s["wall_vx"] / reader.info.V_s)


def open_fork(run_dir: Path | str, slip: int, perm: float | None = None) -> tuple[Branch, Branch]:
    """(drained, undrained) branches of ``RUN/forks/slip_NNN``; ``perm`` picks the undrained
    branch (default: the only one)."""
    run_dir = Path(run_dir)
    fork = RunLayout(run_dir).fork(slip).root
    if not fork.is_dir():
        with RunReader(run_dir, allow_running=True) as r:
            find_slip(read_catalog(r), slip)          # names the slips there are, if slip is not one
        raise MovieError(f"{run_dir} has no fork of slip {slip}; run `gouge restart {run_dir} --slip {slip} "
                         f"--perm K` first")
    dry, wet = fork_branches(fork)
    if perm is not None:
        wet = [p for p in wet if branch_perm(p) == perm]
    if dry is None or not wet:
        have = ", ".join(p.name for p in sorted(fork.iterdir()) if p.is_dir()) or "none"
        raise MovieError(f"{fork} needs a drained and an undrained branch{'' if perm is None else ' ' + branch_name(perm)}; "
                         f"it has: {have}")
    if len(wet) > 1:
        raise MovieError(f"{fork} has several undrained branches ({', '.join(p.name for p in wet)}); pick one "
                         "with --perm")
    drained = _branch("drained", dry)
    undrained = _branch(f"undrained, κ_c = {perm_text(branch_perm(wet[0]))} d²", wet[0])
    return drained, undrained


def frame_times(drained: Branch, undrained: Branch, pad: float = 0.15) -> np.ndarray:
    """tau of every frame: the snapshots of both branches from pad slip durations before the
    first onset to the last snapshot, merged where closer than a third of the snapshot spacing."""
    taus = np.sort(np.concatenate([drained.tau, undrained.tau]))
    spacing = np.median(np.diff(taus)) if taus.size > 1 else 1.0
    span = max(float(taus.max()), 1.0)
    late = taus[taus >= -pad * span]
    if not late.size:
        raise MovieError(f"no snapshot of either branch shows the slip: the last is {-float(taus.max()):.4g} t0 "
                         "before the onset; run the fork again (`gouge restart ... --force`) with "
                         "output.slip_frames > 0, which writes frames while the wall slips")
    taus = late
    keep = [taus[0]]
    for t in taus[1:]:
        if t - keep[-1] > spacing / 3:
            keep.append(t)
    return np.array(keep)


def pressure_scale(branch: Branch) -> float:
    """Largest |P|/sigma over the branch's snapshots (the movie's fixed colour scale)."""
    h5 = branch.reader.h5["snapshots"]
    vmax = max((float(np.abs(branch.reader.snapshot_array(n, "pressure")).max()) for n in branch.names
                if "pressure" in h5[n]), default=0.0)
    return vmax / branch.reader.info.sigma or 1e-6


class FrameRenderer:
    """Draws frames of a fixed pixel size (FRAME_PX) for a pair of branches."""

    def __init__(self, drained: Branch, undrained: Branch, title: str = ""):
        self.branches = (drained, undrained)
        self.width = drained.reader.info.width
        self.sigma = drained.reader.info.sigma
        self.vmax = pressure_scale(undrained)
        self.title = title
        first = drained.reader.snapshot(drained.names[0])
        self.z_lo = float(np.min(first["z"] - first["radius"])) - 0.5
        self.z_hi = float(np.max(first["z"] + first["radius"])) + 1.5
        d = 2.0 * float(np.mean(first["radius"]))
        self.force_unit = self.sigma * d            # [E d^2]: sigma on one grain diameter
        self.fig = plt.figure(figsize=(FRAME_PX[0] / MOVIE_DPI, FRAME_PX[1] / MOVIE_DPI), dpi=MOVIE_DPI)

    def render(self, tau: float) -> np.ndarray:
        """The frame at tau [t0 since onset] as an RGB array (H, W, 3) uint8."""
        fig = self.fig
        fig.clf()
        mesh = None
        for k, branch in enumerate(self.branches):
            ax = fig.add_axes([0.05 + 0.47 * k, 0.29, 0.42, 0.56])
            snap = branch.reader.snapshot(branch.nearest(tau))
            if snap.get("pressure") is not None:
                mesh = draw_pressure(ax, snap, self.width, self.sigma, self.vmax)
                _, ze = pressure_grid(snap, self.width)
            draw_discs(ax, snap, self.width, free_alpha=0.2)
            segments, force = chain_segments(snap, self.width)
            keep = force > MIN_FORCE_FRACTION * self.force_unit
            widths = np.minimum(FORCE_SCALE_PT * force[keep] / self.force_unit, MAX_LINE_PT)
            ax.add_collection(LineCollection(segments[keep], linewidths=widths, colors=CHAIN, capstyle="round",
                                             zorder=3))
            ax.set_xlim(0.0, self.width)
            ax.set_ylim(self.z_lo, self.z_hi)
            ax.set_aspect("equal", adjustable="box")
            ax.tick_params(labelsize=7)
            ax.set_xlabel(LABEL["x"], fontsize=8)
            if k == 0:
                ax.set_ylabel(LABEL["z"], fontsize=8)
            own = float(snap["time"]) - branch.onset
            ax.set_title(f"{branch.label}\nt − t_onset = {own:+.0f} t₀", fontsize=10,
                         color=DRAINED if k == 0 else UNDRAINED)
        if mesh is not None:
            cax = fig.add_axes([0.93, 0.29, 0.012, 0.56])
            cb = fig.colorbar(mesh, cax=cax)
            cb.set_label(LABEL["pressure"], fontsize=8)
            cb.ax.tick_params(labelsize=7)
        inset = fig.add_axes([0.08, 0.07, 0.84, 0.15])
        for branch, color in zip(self.branches, (DRAINED, UNDRAINED)):
            inset.plot(branch.series_tau, branch.series_v, color=color, lw=1.0)
            inset.plot([tau], [np.interp(tau, branch.series_tau, branch.series_v)], "o", color=color, ms=6)
        lo = min(float(b.tau.min()) for b in self.branches)
        hi = max(float(b.tau.max()) for b in self.branches)
        inset.set_xlim(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
        inset.axvline(tau, color="0.5", lw=0.8)
        inset.set_xlabel("t − t_onset  / t₀", fontsize=8)
        inset.set_ylabel("v_w / V_s", fontsize=8)
        inset.tick_params(labelsize=7)
        inset.grid(True, color="0.9")
        fig.text(0.5, 0.99, f"{self.title}   t − t_onset = {tau:+.0f} t₀", ha="center", va="top", fontsize=11)
        fig.text(0.5, 0.955, f"force chains: line width {FORCE_SCALE_PT:g} pt per σ·d = {self.force_unit:.3g} E d² "
                             f"(capped at {MAX_LINE_PT:g} pt; below {MIN_FORCE_FRACTION:g} σ·d not drawn); "
                             f"P/σ colour scale ±{self.vmax:.3g} fixed", ha="center", va="top", fontsize=8,
                 color="0.3")
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self):
        plt.close(self.fig)


def _encoder(path: Path, fps: int):
    """(write(frame), close(), path): MP4 through imageio-ffmpeg, else a GIF through Pillow."""
    try:
        import imageio_ffmpeg
    except ImportError:
        imageio_ffmpeg = None
    if imageio_ffmpeg is not None and path.suffix != ".gif":
        writer = imageio_ffmpeg.write_frames(str(path), FRAME_PX, fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                             output_params=["-crf", "28"], macro_block_size=8)
        writer.send(None)
        return writer.send, writer.close, path
    from PIL import Image

    path = path.with_suffix(".gif")
    frames: list = []

    def close():
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0)

    return lambda f: frames.append(Image.fromarray(f).quantize(colors=128)), close, path


BYTES_PER_FRAME = {".mp4": 60_000, ".gif": 400_000}    # upper sizes of an encoded frame (free-space check)


def is_movie(path: Path) -> bool:
    """Whether `path` is an MP4 or GIF file (what `gouge movie` writes), by its first bytes."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(12)
    except OSError:
        return False
    return head[4:8] == b"ftyp" or head[:4] == b"GIF8"


def make_movie(run_dir: Path | str, slip: int, perm: float | None = None, out: Path | str | None = None,
               fps: int = FPS, max_frames: int | None = None, progress: bool = True, force: bool = False,
               command: str | None = None) -> tuple[Path, int]:
    """Write the movie of slip ``slip`` (default ``RUN/figures/slip_NNN_movie.mp4``, RUN as given);
    returns (path, frames). ``progress``: a plain line on stderr every few seconds. An existing
    ``out`` is replaced only if it is a movie and ``force`` is given (or it is the default path);
    the frames are encoded into a temporary file beside it, renamed when complete
    (:mod:`gouge_cli.io.outputs`); ``command``: what a full disk names to continue."""
    default = out is None
    out = Path(out) if out else Path(run_dir) / "figures" / f"slip_{slip:03d}_movie.mp4"
    check_out(out, is_movie, "a movie (MP4 or GIF)", force, default=default)
    drained, undrained = open_fork(run_dir, slip, perm)
    try:
        taus = frame_times(drained, undrained)
        if max_frames:
            taus = taus[:max_frames]
        next_step = f"run `{command or f'gouge movie {run_dir} --slip {slip}'}` again"
        final = _encoded_path(out)
        require_space(final.parent, len(taus) * BYTES_PER_FRAME.get(final.suffix, BYTES_PER_FRAME[".mp4"]),
                      f"a movie of {len(taus)} frames", next_step)
        out.parent.mkdir(parents=True, exist_ok=True)
        renderer = FrameRenderer(drained, undrained, title=f"{Path(run_dir).name}, slip {slip}")
        try:
            with temporary(final, next_step) as tmp:
                write, close, _ = _encoder(tmp, fps)
                try:
                    ticker = ItemProgress(f"movie slip {slip}: frames", len(taus), quiet=not progress)
                    for done, tau in enumerate(taus):
                        ticker.update(done)
                        write(renderer.render(float(tau)))
                finally:
                    close()
                _check_complete(tmp, final)
        finally:
            renderer.close()
    finally:
        drained.reader.close()
        undrained.reader.close()
    return final, len(taus)


def mp4_complete(path: Path) -> bool:
    """Whether an MP4 file is whole: its top-level boxes tile the file exactly and include the
    header ('ftyp') and the index ('moov', which ffmpeg writes last). An encoder whose disk
    filled leaves a file without it that no player decodes."""
    try:
        size = path.stat().st_size
        seen, at = set(), 0
        with open(path, "rb") as fh:
            while at < size:
                fh.seek(at)
                head = fh.read(16)
                if len(head) < 8:
                    return False
                length, kind = int.from_bytes(head[:4], "big"), head[4:8]
                if length == 1:
                    length = int.from_bytes(head[8:16], "big")
                elif length == 0:
                    length = size - at
                if length < 8 or at + length > size:
                    return False
                seen.add(kind)
                at += length
    except OSError:
        return False
    return {b"ftyp", b"moov"} <= seen


def _check_complete(encoded: Path, final: Path):
    """Raise where the encoder left an incomplete movie: ENOSPC (a disk that filled while it
    encoded: io.outputs.temporary names what to free), else a RuntimeError."""
    import errno

    from ..io.outputs import SPACE_MARGIN, free_bytes

    if final.suffix == ".gif" or mp4_complete(encoded):
        return
    if free_bytes(final.parent) < SPACE_MARGIN:
        raise OSError(errno.ENOSPC, "no space left on device (the encoder stopped)", str(final))
    raise RuntimeError(f"the MP4 encoder left an incomplete file for {final} (ffmpeg failed); nothing was written")


def _encoded_path(path: Path) -> Path:
    """The file the encoder writes for `path`: itself, or with .gif where no MP4 encoder is installed."""
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        return path.with_suffix(".gif")
    return path if path.suffix == ".gif" else path
