"""`gouge export` (VTKHDF for ParaView) and `gouge movie` (one slip, drained | undrained).

Registered on the main typer app by :func:`register` (called at the end of cli/main.py).
Bad input (not a run, no snapshots, no such fork or slip) exits with code 2.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Optional

import typer


def _branches(run_dir: Path, fork: Optional[str]) -> list[Path]:
    """The run directory, or with --fork the branch directories it names under RUN/forks."""
    from ..errors import NotARunError
    from ..io.layout import ForkLayout, RunLayout

    if fork is None:
        return [run_dir]
    layout = RunLayout(run_dir)
    target = layout.forks / fork
    if RunLayout(target).run_file.is_file():
        return [target]
    branches = [p.parent for p in ForkLayout(target).branch_run_files()] if target.is_dir() else []
    if not branches:
        listed = sorted(str(p.parent.relative_to(layout.forks)) for p in layout.branch_run_files())
        raise NotARunError(f"no fork {fork!r} under {layout.forks}; forks there: {', '.join(listed) or 'none'}")
    return branches


def register(app: typer.Typer) -> None:
    """Add the `export` and `movie` commands to ``app``."""

    from .common import guarded

    @app.command()
    @guarded
    def export(
        run_dir: Path = typer.Argument(..., help="run directory"),
        fork: Optional[str] = typer.Option(None, "--fork", help="a fork branch under RUN/forks, e.g. "
                                           "slip_003/perm_1e-05, or slip_003 for all its branches"),
        fmt: str = typer.Option("vtkhdf", "--format", help="file format (vtkhdf: VTK HDF5, read by ParaView)"),
        out: Optional[Path] = typer.Option(None, "--out", help="output file (one branch only; default "
                                           "RUN/export/<run>.vtkhdf or RUN/export/slip_NNN_<branch>.vtkhdf)"),
        split: bool = typer.Option(False, "--split", help="one temporal PolyData file per block (grains, "
                                   "contacts, walls, pressure_grid) instead of one collection"),
        force: bool = typer.Option(False, "--force", help="replace an existing --out file that is a gouge "
                                   "export (never anything else)"),
    ):
        """Write a run's (or fork branch's) snapshots as one time-dependent VTKHDF file for ParaView:
        grains, contacts (normal and tangential force), walls, pressure grid; time in t0 since loading began."""
        from ..errors import AnalysisError, DamagedFileError
        from ..export.vtkhdf import export_run
        from .common import fail, out as console

        if fmt != "vtkhdf":
            fail(f"--format {fmt!r}: the only format is vtkhdf")
        try:
            targets = _branches(Path(run_dir), fork)
            if out is not None and len(targets) > 1:
                fail(f"--out names one file, but --fork {fork} has {len(targets)} branches; give one branch")
            for target in targets:
                command = shlex.join(["gouge", "export", str(run_dir)] + (["--fork", fork] if fork else [])
                                     + (["--out", str(out), "--force"] if out is not None else [])
                                     + (["--split"] if split else []))
                result = export_run(target, out, split=split, force=force, command=command)
                counts = ", ".join(f"{k} {v}" for k, v in result.blocks.items())
                console.print(f"{', '.join(map(str, result.paths))}: {result.times.size} steps, t = {result.times[0]:.6g} .. "
                              f"{result.times[-1]:.6g} t0 since loading began (last step: {counts} points)",
                              highlight=False)
        except (AnalysisError, DamagedFileError) as exc:
            fail(str(exc))

    @app.command()
    @guarded
    def movie(
        run_dir: Path = typer.Argument(..., help="run directory whose slip was forked (`gouge restart`)"),
        slip: int = typer.Option(..., "--slip", help="slip number (see `gouge slips RUN`)"),
        perm: Optional[float] = typer.Option(None, "--perm", help="kappa_c [d^2] of the undrained branch "
                                             "(default: the only one)"),
        out: Optional[Path] = typer.Option(None, "--out", help="output file (default "
                                           "RUN/figures/slip_NNN_movie.mp4; .gif for a GIF)"),
        fps: int = typer.Option(12, "--fps", min=1, max=60, help="frames per second"),
        force: bool = typer.Option(False, "--force", help="replace an existing --out file that is a movie "
                                   "(MP4 or GIF; never anything else)"),
    ):
        """MP4 of one slip, drained and undrained side by side from the same packing: force chains,
        pore pressure P/sigma on a fixed colour scale, time since onset, v_w/V_s with a moving marker."""
        from ..errors import AnalysisError, DamagedFileError
        from ..io.layout import perm_text
        from ..plots.movie import make_movie
        from .common import fail, out as console

        try:
            command = shlex.join(["gouge", "movie", str(run_dir), "--slip", str(slip)]
                                 + (["--perm", perm_text(perm)] if perm is not None else [])
                                 + (["--out", str(out), "--force"] if out is not None else [])
                                 + (["--fps", str(fps)] if fps != 12 else []))
            path, frames = make_movie(run_dir, slip, perm, out, fps=fps, force=force,      # progress lines on stderr
                                      command=command)
        except (AnalysisError, DamagedFileError) as exc:
            fail(str(exc))
        console.print(f"{path}: {frames} frames at {fps} fps ({path.stat().st_size / 1e6:.2f} MB)", highlight=False)


_CLOCK_KEYS = ("onset_time", "end_time", "peak_time", "checkpoint_time")


def catalog_since_loading(run_dir: Path, catalog=None) -> tuple[list[dict], float]:
    """The run's slip catalog (`catalog`, a list of io.slipcatalog.SlipEntry; read from the run when
    None) as dicts with every time in t0 since loading began, velocities in V_s
    (peak_velocity_over_Vs, mean_velocity_over_Vs, subevent_velocity_over_Vs in place of the v0
    values) and NaN as None (valid JSON); returns (catalog, the clock at which loading began)."""
    from ..errors import AnalysisError
    from ..io.runreader import RunReader
    from ..errors import RunDirError
    from ..io.filedoc import json_safe
    from ..io.slipcatalog import slip_catalog

    try:
        with RunReader(run_dir, allow_running=True) as reader:
            origin = reader.time_offset()
            V_s = reader.info.V_s
    except AnalysisError as exc:
        raise RunDirError(str(exc)) from None
    catalog = [e.to_dict() for e in (slip_catalog(run_dir) if catalog is None else catalog)]
    for entry in catalog:
        for key in _CLOCK_KEYS:
            entry[key] -= origin
        entry["subevent_time"] = [t - origin for t in entry["subevent_time"]]
        for key in ("peak_velocity", "mean_velocity"):
            entry[f"{key}_over_Vs"] = entry.pop(key) / V_s
        entry["subevent_velocity_over_Vs"] = [v / V_s for v in entry.pop("subevent_velocity")]
        entry["time_origin"] = "loading start"
    return json_safe(catalog), origin


def print_config_doc(schema: Optional[Path]) -> None:
    """`gouge config --defaults` (commented YAML) or `--schema PATH` (JSON Schema; '-' = stdout)."""
    import json

    from ..config_doc import commented_defaults, json_schema

    if schema is None:
        print(commented_defaults(), end="")
        return
    text = json.dumps(json_schema(), indent=2) + "\n"
    if str(schema) == "-":
        print(text, end="")
        return
    schema.parent.mkdir(parents=True, exist_ok=True)
    schema.write_text(text)
    print(f"wrote {schema} (JSON Schema of a gouge config; in YAML files add the first line "
          f"'# yaml-language-server: $schema={schema.resolve()}')")
