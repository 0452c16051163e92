"""`gouge export` read back through VTK's own vtkHDFReader, `gouge movie` frames and encoding,
self-describing run files and checkpoints, and the time origin of `gouge slips`."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.cli.main import app
from gouge_cli.errors import EXIT_BAD_INPUT
from factories import branch_at

SCENE = {
    "name": "tinywet",
    "seed": 3,
    "packing": {"n_grains": 160, "width": 10},
    "loading": {"spring_constant": 2e-4, "velocity": 4e-5},
    "numerics": {"dt_safety": 0.3},
    "run": {"duration": 2000},
    "output": {"series_interval": 10, "snapshot_interval": 500, "checkpoint_interval": 1000, "slip_frames": 5},
    "fluid": {"permeability": 1e-5, "cell_size": 2.5},
}
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A wet and a dry run of one small scene (same packing, 2,000 t0 of loading), and the two
    as a fork (_fake_fork)."""
    from gouge_cli.errors import MovieError
    from gouge_cli.plots.movie import frame_times, open_fork

    root = tmp_path_factory.mktemp("export")
    cfg = root / "tinywet.yaml"
    for k in range(6):      # a packing whose two runs, taken as a fork, give the movie frames
        for name in ("wet", "dry", "forked"):
            shutil.rmtree(root / name, ignore_errors=True)
        cfg.write_text(yaml.safe_dump(dict(SCENE, seed=SCENE["seed"] + k)))
        for name, extra in (("wet", []), ("dry", ["--set", "fluid=none"])):
            result = gouge("run", cfg, "--out", root / name, "--quiet", *extra)
            assert result.exit_code == 0, result.output
        drained, undrained = open_fork(_fake_fork(root), 1, 1e-5)
        try:
            frame_times(drained, undrained)
            return root
        except MovieError:
            pass
        finally:
            drained.reader.close()
            undrained.reader.close()
    pytest.fail("no packing of the scene gave its fork movie a frame")


def clock_tolerance(steps, *times) -> float:
    """How far apart two clocks that each add dt once per step may drift in `steps` steps: every
    addition rounds by at most half an ulp of its result (the larger clock's, times[...]), two
    clocks, plus a few roundings of the subtractions that compare them."""
    return (steps + 4) * float(np.spacing(max(abs(float(t)) for t in times)))


def _read_vtkhdf(path, times, tol):
    """[{block: vtkPolyData} per time step] through vtkHDFReader: the time steps it announces
    (within tol of times), then each step by SetStep (the time of the output it gives is checked too)."""
    vtk = pytest.importorskip("vtk")
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as SDDP

    reader = vtk.vtkHDFReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    steps = np.array(reader.GetOutputInformation(0).Get(SDDP.TIME_STEPS()))
    assert np.all(np.abs(steps - times) <= tol) and reader.GetNumberOfSteps() == len(times)
    out = []
    for k, t in enumerate(steps):
        reader.SetStep(k)
        reader.Update()
        pdc = reader.GetOutputDataObject(0)
        assert pdc.GetInformation().Get(vtk.vtkDataObject.DATA_TIME_STEP()) == t
        blocks = {}
        for b in range(pdc.GetNumberOfPartitionedDataSets()):
            ds = vtk.vtkPolyData()
            ds.DeepCopy(pdc.GetPartition(b, 0))
            blocks[pdc.GetMetaData(b).Get(vtk.vtkCompositeDataSet.NAME())] = ds
        out.append(blocks)
    return out


def test_split_export_serves_time_requests(runs, tmp_path):
    """--split: per-block PolyData files; a downstream filter asking for a time gets that step."""
    vtk = pytest.importorskip("vtk")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as SDDP

    result = gouge("export", runs / "wet", "--split", "--out", tmp_path / "w.vtkhdf")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in tmp_path.glob("*.vtkhdf")) == [
        "w_contacts.vtkhdf", "w_grains.vtkhdf", "w_pressure_grid.vtkhdf", "w_walls.vtkhdf"]
    with h5py.File(runs / "wet" / "run.h5", "r") as h5:
        names = sorted(h5["snapshots"])
        vx = [h5["snapshots"][n]["vx"][...] for n in names]
        times = [h5["snapshots"][n].attrs["load_time"] for n in names]
    reader = vtk.vtkHDFReader()
    reader.SetFileName(str(tmp_path / "w_grains.vtkhdf"))
    follow = vtk.vtkPassThrough()
    follow.SetInputConnection(reader.GetOutputPort())
    follow.UpdateInformation()
    assert np.allclose(follow.GetOutputInformation(0).Get(SDDP.TIME_STEPS()), times, rtol=0, atol=1e-9)
    for k in (len(times) - 1, 0, 2):
        follow.UpdateTimeStep(times[k])
        got = vtk_to_numpy(follow.GetOutputDataObject(0).GetPointData().GetArray("velocity"))[:, 0]
        assert np.array_equal(got, vx[k])


def _array(data, name):
    from vtkmodules.util.numpy_support import vtk_to_numpy

    arr = data.GetArray(name)
    assert arr is not None, name
    return vtk_to_numpy(arr)


def test_export_reads_back_through_vtk(runs):
    from vtkmodules.util.numpy_support import vtk_to_numpy

    result = gouge("export", runs / "wet")
    assert result.exit_code == 0, result.output
    path = runs / "wet" / "export" / "wet.vtkhdf"
    with h5py.File(runs / "wet" / "run.h5", "r") as h5:
        origin = h5["series/time"][0] - h5["series/load_time"][0]
        names = sorted(h5["snapshots"])
        snaps = [{k: v[...] for k, v in h5["snapshots"][n].items()} for n in names]
        geometry = [dict(h5["snapshots"][n]["pressure"].attrs) for n in names]
        times = np.array([h5["snapshots"][n].attrs["time"] - origin for n in names])
        # the export's times are the drive clock (load_time), ours the main clock minus its value
        # when loading began: two sums of dt that drift apart by round-off
        tol = clock_tolerance(max(h5["snapshots"][n].attrs["step"] for n in names),
                              *(h5["snapshots"][n].attrs["time"] for n in names))
        width, sigma = h5.attrs["width"], SCENE.get("loading", {}).get("normal_stress", 3e-4)
    assert len(names) >= 5 and abs(times[0]) <= tol
    data = _read_vtkhdf(path, times, tol)
    assert len(data) == len(snaps)
    for blocks, snap, geo in zip(data, snaps, geometry):
        assert set(blocks) == {"grains", "contacts", "walls", "pressure_grid"}
        grains = blocks["grains"]
        n = snap["x"].size
        assert grains.GetNumberOfPoints() == n == SCENE["packing"]["n_grains"]
        assert grains.GetNumberOfCells() == n
        pd = grains.GetPointData()
        assert np.array_equal(_array(pd, "grain_id"), np.arange(n))          # original numbering
        assert np.array_equal(_array(pd, "radius"), snap["radius"])
        assert np.array_equal(_array(pd, "velocity")[:, :2], np.column_stack([snap["vx"], snap["vz"]]))
        assert np.array_equal(_array(pd, "body"), snap["body"])
        pts = vtk_to_numpy(grains.GetPoints().GetData())
        assert np.allclose(pts[:, 0], np.mod(snap["x"], width), atol=1e-12) and np.array_equal(pts[:, 1], snap["z"])
        # contact count and net force per grain from the pair list
        m = snap["contact_i"].size
        count = np.bincount(snap["contact_i"], minlength=n) + np.bincount(snap["contact_j"], minlength=n)
        assert np.array_equal(_array(pd, "contact_count"), count)
        net_z = np.bincount(snap["contact_j"], snap["contact_fz"], n) - np.bincount(snap["contact_i"], snap["contact_fz"], n)
        assert np.allclose(_array(pd, "contact_force")[:, 1], net_z, rtol=0, atol=1e-15)
        # contacts: one line per pair; normal force = F . (x_j - x_i)/|x_j - x_i| (nearest image)
        contacts = blocks["contacts"]
        assert contacts.GetNumberOfCells() == m and contacts.GetNumberOfPoints() == 2 * m
        cd = contacts.GetCellData()
        assert set(cd.GetArrayName(k) for k in range(cd.GetNumberOfArrays())) == {
            "normal_force", "tangential_force", "force", "grain_i", "grain_j"}
        dx = snap["x"][snap["contact_j"]] - snap["x"][snap["contact_i"]]
        dx -= width * np.round(dx / width)
        dz = snap["z"][snap["contact_j"]] - snap["z"][snap["contact_i"]]
        fn = (snap["contact_fx"] * dx + snap["contact_fz"] * dz) / np.hypot(dx, dz)
        assert np.allclose(_array(cd, "normal_force"), fn, rtol=1e-12, atol=0)
        assert (fn > 0).mean() > 0.9                                      # contacts push apart
        f = np.hypot(snap["contact_fx"], snap["contact_fz"])
        assert np.allclose(np.hypot(_array(cd, "normal_force"), _array(cd, "tangential_force")), f, rtol=1e-12)
        assert np.array_equal(_array(cd, "grain_i"), snap["contact_i"])
        # pressure grid: nx*nz quads at the stored origin and spacing
        grid = blocks["pressure_grid"]
        nx, nz = snap["pressure"].shape
        assert grid.GetNumberOfCells() == nx * nz and grid.GetNumberOfPoints() == (nx + 1) * (nz + 1)
        assert np.array_equal(_array(grid.GetCellData(), "pressure"), snap["pressure"].ravel())
        assert np.allclose(_array(grid.GetCellData(), "pressure_over_sigma"), snap["pressure"].ravel() / sigma)
        gp = vtk_to_numpy(grid.GetPoints().GetData())
        assert gp[:, 0].min() == 0.0 and gp[:, 0].max() == pytest.approx(width, rel=1e-12)
        assert gp[:, 1].min() == geo["origin"][1]
        assert gp[:, 1].max() == pytest.approx(geo["origin"][1] + nz * geo["spacing"][1], rel=1e-12)
        assert blocks["walls"].GetNumberOfCells() == 2


def test_export_bad_input(runs, tmp_path):
    assert gouge("export", tmp_path).exit_code == EXIT_BAD_INPUT
    bad = gouge("export", runs / "wet", "--fork", "slip_009/perm_1")
    assert bad.exit_code == EXIT_BAD_INPUT and "no fork" in bad.output
    assert gouge("export", runs / "wet", "--format", "vtu").exit_code == EXIT_BAD_INPUT


def test_every_dataset_and_attribute_is_described(runs):
    for path in (runs / "wet" / "run.h5", runs / "dry" / "run.h5", runs / "wet" / "checkpoints" / "latest.h5"):
        missing = []
        with h5py.File(path, "r") as h5:
            def visit(name, obj):
                if isinstance(obj, h5py.Dataset) and not ("unit" in obj.attrs and "description" in obj.attrs):
                    missing.append(name)
                if set(obj.attrs) - {"unit", "description", "attrs_sha256"} and not isinstance(obj, h5py.Dataset):
                    documented = json.loads(obj.attrs["attribute_units"])
                    for key in obj.attrs:
                        if key not in ("attribute_units", "unit", "description", "attrs_sha256"):   # the seal (docs: integrity)
                            assert documented.get(key, ["-", "undocumented"])[1] != "undocumented", (name, key)

            visit("/", h5)
            h5.visititems(visit)
            if path.name == "run.h5":
                assert json.loads(h5.attrs["body_codes"])["2"].startswith("top-wall")
                assert "since loading began" in h5.attrs["time_origin"]
        assert not missing, (path, missing[:5])
    with h5py.File(runs / "wet" / "run.h5", "r") as h5:
        snap = h5["snapshots"][sorted(h5["snapshots"])[-1]]
        p = snap["pressure"]
        assert p.attrs["unit"] == "E" and p.attrs["axis_order"] == "x, z"
        nx, nz = p.shape
        assert p.attrs["spacing"][0] * nx == pytest.approx(h5.attrs["width"], rel=1e-12)
        # the grid spans the wall planes (mean z of the wall grains) at the last fluid update
        zb, zt = snap["z"][snap["body"][...] == 1].mean(), snap["z"][snap["body"][...] == 2].mean()
        assert p.attrs["origin"][1] == pytest.approx(zb, abs=1e-6)
        assert p.attrs["origin"][1] + nz * p.attrs["spacing"][1] == pytest.approx(zt, abs=0.05)
        tol = clock_tolerance(snap.attrs["step"], snap.attrs["time"])      # two clocks, each a sum of dt
        assert abs(snap.attrs["load_time"] - (snap.attrs["time"] - h5.attrs["load_start_time"])) <= tol


def _fake_fork(runs):
    """RUN/forks/slip_001/{drained,perm_1e-05} from the dry and wet runs (same packing)."""
    fork = runs / "forked" / "forks" / "slip_001"
    if not fork.exists():
        shutil.copytree(runs / "wet", runs / "forked", ignore=shutil.ignore_patterns("forks", "export"))
        shutil.copytree(runs / "dry", fork / "drained")
        shutil.copytree(runs / "wet", fork / "perm_1e-05")
    return runs / "forked"


def test_movie_frame_and_encoding(runs):
    from gouge_cli.plots.movie import FRAME_PX, FrameRenderer, frame_times, make_movie, open_fork

    run = _fake_fork(runs)
    drained, undrained = open_fork(run, 1, 1e-5)
    try:
        renderer = FrameRenderer(drained, undrained, "test")
        frame = renderer.render(0.0)
        renderer.close()
        assert frame.shape == (FRAME_PX[1], FRAME_PX[0], 3) and frame.dtype == np.uint8
        assert frame.std() > 10                                   # something was drawn
        taus = frame_times(drained, undrained, pad=0.15)
        # the rule (how many frames there are depends on where the slip falls in the run): the
        # snapshots of both branches from 0.15 spans before the onset, merged closer than a third
        # of their median spacing, so every such snapshot lies within that third of a frame
        every = np.sort(np.concatenate([drained.tau, undrained.tau]))
        third = np.median(np.diff(every)) / 3
        kept = every[every >= -0.15 * max(float(every.max()), 1.0)]
        assert taus.size >= 1 and taus[0] == kept[0] and np.all(np.isin(taus, kept))
        assert np.all(np.diff(taus) > third)
        assert all(np.abs(taus - t).min() <= third for t in kept)
    finally:
        drained.reader.close()
        undrained.reader.close()
    wanted = min(4, taus.size)
    path, frames = make_movie(run, 1, 1e-5, runs / "m.mp4", max_frames=4)
    assert path.suffix == ".mp4" and frames == wanted and 1e3 < path.stat().st_size < 2e6
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert tuple(meta["size"]) == FRAME_PX
    assert sum(1 for _ in reader) == wanted
    gif, frames = make_movie(run, 1, None, runs / "m.gif", max_frames=2)      # the fallback format
    from PIL import Image

    with Image.open(gif) as im:
        assert gif.suffix == ".gif" and im.n_frames == frames == min(2, taus.size) and im.size == FRAME_PX
    bad = gouge("movie", run, "--slip", 2)
    assert bad.exit_code == EXIT_BAD_INPUT and ("no fork of slip 2" in bad.output or "no slip number 2" in bad.output)


def test_slips_json_is_valid_and_counts_from_loading(runs):
    from gouge_cli.cli.export_cmds import catalog_since_loading
    from gouge_cli.io.slipcatalog import SlipEntry
    from gouge_cli.model.slip_rule import SubEvent

    listed = gouge("slips", runs / "dry", "--json")
    assert listed.exit_code == 0
    json.loads(listed.output, parse_constant=lambda c: pytest.fail(f"invalid JSON constant {c}"))
    with h5py.File(runs / "dry" / "run.h5", "r") as h5:
        origin = h5["series/time"][0] - h5["series/load_time"][0]
    assert origin > 500                                       # compaction took at least min_time
    nan = float("nan")
    entry = SlipEntry(onset_index=0, onset_time=origin + 5.0, end_index=1, end_time=origin + 9.0, duration=4.0,
                      slip=nan, peak_velocity=nan, peak_index=0, peak_time=origin + 7.0, mean_velocity=nan,
                      static_strength=nan, tau_onset=nan, tau_min=nan, stress_drop=nan, porosity_change=nan,
                      subevents=(SubEvent(-1, origin + 7.0, nan),), number=1)
    catalog, got = catalog_since_loading(runs / "dry", [entry])
    assert got == origin
    (e,) = catalog
    assert (e["onset_time"], e["end_time"], e["peak_time"]) == pytest.approx((5.0, 9.0, 7.0), abs=1e-9)
    assert e["checkpoint_time"] is None and e["deborah"] is None and e["subevent_time"] == pytest.approx([7.0])
    json.dumps(catalog, allow_nan=False)


def test_export_fork_exports_each_branch(runs):
    run = _fake_fork(runs)
    result = gouge("export", run, "--fork", "slip_001")
    assert result.exit_code == 0, result.output
    written = [line.split(":")[0] for line in result.output.splitlines() if ".vtkhdf" in line]
    assert len(written) == 2 and all(Path(p).is_file() for p in written)
    one = gouge("export", run, "--fork", "slip_001/perm_1e-05", "--out", runs / "one.vtkhdf")
    assert one.exit_code == 0 and (runs / "one.vtkhdf").is_file()
    assert gouge("export", run, "--fork", "slip_001", "--out", runs / "two.vtkhdf").exit_code == EXIT_BAD_INPUT


def test_export_of_a_fork_lands_in_its_run_whatever_the_working_directory(runs, monkeypatch, tmp_path):
    """A real fork stores parent_run relative to the branch directory ("../../.."): the export goes to
    RUN/export, not to that path taken from the working directory."""
    import h5py

    from gouge_cli.io import integrity

    run = _fake_fork(runs)
    branch = branch_at(run, 1, 1e-5).root
    with h5py.File(branch / "run.h5", "r+") as h5:
        h5.attrs["parent_run"] = "../../.."
        h5.attrs["fork_slip"] = 1
        h5.attrs["branch"] = "perm_1e-05"
        integrity.seal(h5)                     # an edit by hand renews the file's checksum
    elsewhere = tmp_path / "a" / "b" / "c"
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    result = gouge("export", run, "--fork", "slip_001/perm_1e-05")
    assert result.exit_code == 0, result.output
    assert (run / "export" / "slip_001_perm_1e-05.vtkhdf").is_file()
    assert not (tmp_path / "export").exists()


def test_movie_without_a_frame_of_the_slip_is_refused():
    """Snapshots that all end before the onset give no frame: MovieError naming the fix, not an
    IndexError (seen on a fork whose branches wrote no slip frames)."""
    from gouge_cli.errors import MovieError
    from gouge_cli.plots.movie import Branch, frame_times

    def branch(*tau):
        return Branch("b", None, 0.0, [f"{k}" for k in range(len(tau))], np.array(tau), np.zeros(0), np.zeros(0))

    with pytest.raises(MovieError, match="slip_frames"):
        frame_times(branch(-500.0, -20.0), branch(-480.0, -5.0))
    assert frame_times(branch(-500.0, 0.1), branch(-480.0, 50.0)).tolist() == [0.1, 50.0]
