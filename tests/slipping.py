"""A scene that slips, for every ``GOUGE_TEST_SEED_OFFSET``.

Whether a small scene slips in a given loading time, and how often, depends on its packing. A
test that needs slips (with checkpoints, to fork them) runs its scene with :func:`slipping_run`,
which tries the next packings (seed + 1, seed + 2, ...) until the catalog holds what the test
needs, so the test asserts what it is about on a run that has it, whatever the offset.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.io.slipcatalog import slip_catalog
from factories import scene

# 300 grains: two or more slips with checkpoints in 80,000 t0 for most packings
TINY = scene("tiny", 4, numerics={"threads": 1}, run={"duration": 80000},
             output={"series_interval": 10, "snapshot_interval": 20000})


def _next_packing(scene: dict, k: int, grow: float) -> dict:
    """Try k of `scene`: seed + k, run.duration `grow`**k times longer."""
    run = dict(scene.get("run", {}))
    if "duration" in run:
        run["duration"] = run["duration"] * grow ** k
    return dict(scene, seed=scene["seed"] + k, run=run)


def slipping_run(scene: dict, root: Path, slips: int = 2, min_drop: float = 0.0, tries: int = 6,
                 args: tuple = (), grow: float = 1.0) -> tuple[Path, Path, list[int]]:
    """(config file, run directory, numbers of the slips kept with checkpoints and a stress drop
    above `min_drop`) of `scene` run with ``gouge run CONFIG --out root/NAME --quiet *args``, at
    the first of `tries` seeds whose catalog holds at least `slips` such slips; each try after
    the first also runs `grow` times longer (for scenes whose first slip comes late for some
    packings). The config file (root/NAME.yaml) holds the seed and duration that were used."""
    root = Path(root)
    config, out = root / f"{scene['name']}.yaml", root / scene["name"]
    counts = []
    for k in range(tries):
        config.write_text(yaml.safe_dump(_next_packing(scene, k, grow)))
        if out.exists():
            shutil.rmtree(out)
        result = CliRunner().invoke(app, ["run", str(config), "--out", str(out), "--quiet", *map(str, args)])
        assert result.exit_code == 0, result.output
        numbers = [e.number for e in slip_catalog(out) if e.checkpoint and e.stress_drop > min_drop]
        if len(numbers) >= slips:
            return config, out, numbers
        counts.append(len(numbers))
    pytest.fail(f"none of {tries} packings of scene {scene['name']!r} gave {slips} slips with checkpoints "
                f"and a stress drop above {min_drop} "
                f"(they gave {counts})")


def slipping_start(scene: dict, root: Path, tries: int = 6, grow: float = 1.5):
    """The accuracy ladders' Start (studies.accuracy.prepare_start) from the checkpoint before the
    first slip of `scene`, at the first of `tries` seeds whose loading (run.duration, `grow` times
    longer each try) brings a slip with a checkpoint."""
    from gouge_cli.config import build_config
    from gouge_cli.studies.accuracy import prepare_start

    sources = []
    for k in range(tries):
        start = prepare_start(build_config(_next_packing(scene, k, grow)), Path(root) / f"seed_{k}")
        if Path(start.source).name.startswith("slip_"):
            return start
        sources.append(Path(start.source).name)
    pytest.fail(f"none of {tries} packings of scene {scene['name']!r} slipped with a checkpoint (starts: {sources})")
