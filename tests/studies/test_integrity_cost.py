"""benchmarks/integrity_cost.py compares what it says: its "with" run files verify sound with
Fletcher-32 and seals, its "without" files have neither (and an empty checkpoint digest), the
switches are undone afterwards, and the two runs hold the same data (the checks change no bit)."""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from benchmark_scripts import load
from gouge_cli.config import build_config
from gouge_cli.io import checkpoint, runwriter
from gouge_cli.io.integrity import SEAL
from gouge_cli.io.verify import verify_run

SCENE = {"name": "cost", "seed": 3, "packing": {"n_grains": 300, "width": 15},
         "loading": {"spring_constant": 2e-4, "velocity": 4e-5}, "numerics": {"threads": 1},
         "run": {"duration": 6000},
         "output": {"series_interval": 10, "snapshot_interval": 2000, "checkpoint_interval": 2000}}


@pytest.fixture(scope="module")
def cost():
    return load("integrity_cost")


def _objects(path):
    found = {}
    with h5py.File(path, "r") as h5:
        h5.visititems(lambda name, obj: found.setdefault(name, (
            isinstance(obj, h5py.Dataset) and bool(obj.fletcher32), SEAL in obj.attrs,
            obj[...] if isinstance(obj, h5py.Dataset) else None)) and None)
        found["/"] = (False, SEAL in h5.attrs, None)
    return found


def test_with_and_without_checks(cost, tmp_path):
    config = build_config(SCENE)
    originals = (runwriter.seal, checkpoint.content_digest, h5py.Group.create_dataset, runwriter.RunFile.flush)
    with_ = cost.one_run(config, tmp_path / "with", True)
    without = cost.one_run(config, tmp_path / "without", False)
    assert (runwriter.seal, checkpoint.content_digest, h5py.Group.create_dataset, runwriter.RunFile.flush) == originals
    for row in (with_, without):
        assert row["write_run_h5_s"] > 0 and row["read_run_h5_s"] > 0
        assert math.isnan(row["analyze_s"]) or row["analyze_s"] > 0     # NaN: no slip, nothing to analyse and row["checkpoints"] >= 1 and row["write_checkpoints_s"] > 0
        assert row["write_run_h5_s"] + row["write_checkpoints_s"] < row["wall_s"]
    assert verify_run(tmp_path / "with")["sound"]
    a, b = _objects(tmp_path / "with/run.h5"), _objects(tmp_path / "without/run.h5")
    assert a.keys() == b.keys()
    assert any(f for f, _, _ in a.values()) and all(s for _, s, _ in a.values())
    assert not any(f for f, _, _ in b.values()) and not any(s for _, s, _ in b.values())
    for name, (_, _, data) in a.items():
        if data is not None and name != "series/wall_clock":
            assert np.array_equal(data, b[name][2], equal_nan=True), name
    with h5py.File(tmp_path / "without/checkpoints/latest.h5", "r") as h5:
        assert h5.attrs["checksum"] == checkpoint.DIGEST_PREFIX
