"""Orchestration of `gouge run`: run directory, compaction, loading, outputs, clean stops."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from .config import Config, dump_config
from .output import RunFile
from .progress import ProgressReport
from .simulation import Every, PhysicsError, Simulation


class RunDirError(ValueError):
    """The run directory cannot be used (exists with results, or is not a run)."""


@dataclass
class RunResult:
    out_dir: Path
    status: str
    steps: int
    wall_seconds: float
    grain_steps_per_second: float
    simulation: Simulation


def default_run_dir(config: Config, runs_root: Path = Path("runs")) -> Path:
    return runs_root / config.name


def prepare_run_dir(out_dir: Path, force: bool = False) -> Path:
    out_dir = Path(out_dir)
    run_file = out_dir / "run.h5"
    if run_file.exists() and not force:
        raise RunDirError(f"{out_dir} already holds a run (run.h5); choose another --out, "
                          "another name (--set name=...), or pass --force to overwrite it")
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir


def run_scene(config: Config, out_dir: Path, force: bool = False, live: bool | None = None,
              quiet: bool = False) -> RunResult:
    """Compact, then load for config.run.duration, writing out_dir/{config.yaml, run.h5}.

    Ctrl-C stops cleanly (status 'interrupted', outputs flushed); a PhysicsError is
    recorded in the run file's status and re-raised.
    """
    out_dir = prepare_run_dir(out_dir, force)
    (out_dir / "config.yaml").write_text(dump_config(config))
    sim = Simulation(config)
    writer = RunFile(out_dir / "run.h5", config, sim.dt,
                     extra_attrs={"n_grains": sim.state.n, "width": sim.state.width,
                                  "wall_mass_per_length": sim.wall_mass_per_length})
    n = sim.state.n
    status = "finished"
    t_start = time.perf_counter()
    steps0 = sim.state.step
    progress = None
    try:
        if not quiet:
            progress = ProgressReport("compaction", config.compaction.max_time, n, live=live)
        sim.compact(on_chunk=(lambda s, el: progress.update(el, s.state.step)) if progress else None)
        if progress:
            progress.close()
        writer.set_attr("compaction_end_time", sim.state.time)

        load_t0 = sim.state.time
        if not quiet:
            progress = ProgressReport(f"loading {config.name}", config.run.duration, n, live=live)

        def record(s: Simulation):
            row = s.observe()
            s.check(row)
            writer.append(row)
            if progress:
                progress.update(s.state.time - load_t0, s.state.step,
                                info=f"tau/sigma {row['tau_over_sigma']:.3f}")

        callbacks = [
            Every(sim.steps_for(config.output.series_interval), record),
            Every(sim.steps_for(config.output.snapshot_interval), writer.snapshot),
        ]
        record(sim)
        writer.snapshot(sim)
        sim.run(config.run.duration, callbacks)
    except KeyboardInterrupt:
        status = "interrupted"
    except PhysicsError as err:
        status = f"failed: {err}"
        raise
    finally:
        if progress:
            progress.close()
        writer.close(status)
    wall = time.perf_counter() - t_start
    steps = sim.state.step - steps0
    return RunResult(out_dir, status, steps, wall, steps * n / max(wall, 1e-9), sim)
