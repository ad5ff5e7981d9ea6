"""3D asphalt (seed 000): servo-wall compaction of carved aggregates, porosity against time."""

from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from demcli import run_case
from demcli.errors import ConfigError, InputError, StageError
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"
SMOKE = CASES / "smoke" / "asphalt_carved_cube.yaml"


def _case(tmp_path, n, edit):
    data = yaml.safe_load(SMOKE.read_text())
    data["stages"] = data["stages"][:n]
    edit(data["stages"])
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_servo_walls_reach_the_target_stress_and_porosity_is_recorded(smoke_run):
    st = read_state(smoke_run / "03-compact.h5")
    rec = st.groups["records/dem"]
    comp = st.groups["compaction"]
    # Then the stage stopped at the servo stress: each servo face's stress (its force over its
    # current area), averaged over the last 10 records, is within 3 % of 0.1 MPa
    assert "servo stress" in str(comp["stopped"])
    for face in ("x1", "y1", "z1"):
        assert np.mean(rec[f"stress_{face}"][-10:]) == pytest.approx(1e5, rel=0.03)
    for ax in "xyz":  # the opposite, fixed faces carry most of it (the rest is wall friction)
        assert 0.5e5 < np.mean(rec[f"stress_{ax}"][-10:]) < 1.2e5
    # and the porosity fell from the loose carving to a dense skeleton
    p = rec["porosity"]
    assert p[0] == pytest.approx(float(comp["porosity_initial"])) and p[0] > 0.8
    assert float(comp["porosity_final"]) < 0.6 and p[-1] == pytest.approx(float(comp["porosity_final"]))
    # walls close in; the box grows back only where the servo overshoots the target stress and
    # backs off (by up to ~1e-3 in porosity between two records, on a fall of ~0.29), far less
    # than a servo pushing the wrong way would
    fall = p[0] - p[-1]
    assert np.all(np.diff(p) <= 0.01 * fall) and p[-1] - np.min(p) <= 0.01 * fall
    # and it is 1 - solid volume / box volume, the box read off the walls
    box = comp["box"]
    vol = np.prod(box[3:] - box[:3])
    assert float(comp["porosity_final"]) == pytest.approx(1 - st["aggregates/volume"].sum() / vol, rel=1e-12)
    assert np.allclose(box[3:] - box[:3], [st["walls/point"][k][d] for k, d in ((1, 0), (3, 1), (5, 2))]
                       - box[:3])
    # and porosity against time is written as CSV and PNG
    csv = smoke_run / "records" / "compact_dem.csv"
    head = csv.read_text().splitlines()[0]
    assert "time[s]" in head and "porosity" in head and "stress_z1[Pa]" in head
    assert (smoke_run / "records" / "compact_dem_porosity.png").stat().st_size > 1000
    # and every sphere is inside the final box (up to small overlaps)
    c = st.sphere_centres()
    r = st["spheres/radius"]
    assert np.all(c - r[:, None] > box[:3] - 0.1 * r[:, None]) and np.all(c + r[:, None] < box[3:] + 0.1 * r[:, None])


def test_compaction_stops_at_a_target_porosity(tmp_path):
    # Given the smoke case with a lid at constant speed and a porosity target
    def edit(stages):
        stages[3]["walls"][0]["motion"] = {"z1": {"mode": "velocity", "velocity": [0, 0, "-0.5 m/s"]}}
        stages[3]["target"] = {"porosity": 0.75}

    run_case(_case(tmp_path, 4, edit), out=tmp_path / "run", quiet=True, threads=1)
    st = read_state(tmp_path / "run" / "03-compact.h5")
    p = st.groups["records/dem"]["porosity"]
    # Then it stopped at the first record below 0.75, long before the end of time
    assert "target porosity" in str(st["compaction/stopped"])
    assert p[-1] <= 0.75 < p[-2]
    assert st.meta["time"] < 0.5 * 0.2


def test_compact_needs_one_closed_box_and_the_aggregates_inside(tmp_path):
    from demcli.stages.base import load_case

    def open_box(stages):
        stages[3]["walls"][0]["open"] = ["z1"]
        stages[3]["walls"][0]["motion"] = {}

    with pytest.raises(ConfigError, match="the box must be closed"):
        load_case(_case(tmp_path, 4, open_box))

    def small_box(stages):
        stages[3]["walls"][0]["max"] = ["20 mm", "30 mm", "30 mm"]

    with pytest.raises(InputError, match="stick out of the box"):
        run_case(_case(tmp_path, 4, small_box), out=tmp_path / "run", quiet=True, threads=1)


def _datasets(path):
    """Every dataset of an HDF5 file as {name: array} (provenance attributes excluded)."""
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


@pytest.fixture(scope="module")
def compaction_case(tmp_path_factory):
    """The smoke case cut after its compaction, and an uninterrupted run of it."""
    tmp = tmp_path_factory.mktemp("compact_resume")
    path = _case(tmp, 4, lambda stages: None)
    run_case(path, out=tmp / "ref", quiet=True, threads=1)
    return path, tmp / "ref"


@pytest.mark.parametrize("at_step", [16000, 21000])
def test_interrupted_compaction_resumes_bit_identically(compaction_case, tmp_path, monkeypatch, at_step):
    from demcli.engine import system as system_mod

    path, ref = compaction_case
    # Given a compaction interrupted (Ctrl-C) at step 16000, while the servo faces switch between
    # closing in and settling (records every 910 steps: the last good state is at a record), or
    # at step 21000, all faces settling towards 0.1 MPa
    real = system_mod.System.advance

    def interrupted(self, n):
        if self.step >= at_step:
            raise KeyboardInterrupt
        return real(self, n)

    monkeypatch.setattr(system_mod.System, "advance", interrupted)
    with pytest.raises(StageError, match="interrupted"):
        run_case(path, out=tmp_path, quiet=True, threads=1)
    assert (tmp_path / "03-compact.ckpt.h5").exists()
    # When it is resumed
    monkeypatch.setattr(system_mod.System, "advance", real)
    run_case(path, out=tmp_path, quiet=True, threads=1, resume=True)
    # Then the compacted state, its records and summary equal the uninterrupted run's bit for bit
    a, b = _datasets(ref / "03-compact.h5"), _datasets(tmp_path / "03-compact.h5")
    assert sorted(a) == sorted(b)
    assert [k for k in a if not np.array_equal(np.asarray(a[k]), np.asarray(b[k]))] == []


def test_compaction_interrupted_while_writing_its_outputs_keeps_its_stop_reason(tmp_path, monkeypatch):
    """Ctrl-C while a compaction that stopped at its target porosity writes its figures: the
    resumed stage writes the outputs only, and says why it stopped as the uninterrupted run."""
    import os
    import signal

    from demcli.state import records

    def edit(stages):
        stages[3]["walls"][0]["motion"] = {"z1": {"mode": "velocity", "velocity": [0, 0, "-0.5 m/s"]}}
        stages[3]["target"] = {"porosity": 0.75}

    path = _case(tmp_path, 4, edit)
    run_case(path, out=tmp_path / "ref", quiet=True, threads=1)
    real = records.RecordTable.write_csv
    sent = []

    def write_csv(self, *args, **kwargs):
        if self.name == "dem" and not sent:  # the compact stage's own record
            sent.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        return real(self, *args, **kwargs)

    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        monkeypatch.setattr(records.RecordTable, "write_csv", write_csv)
        with pytest.raises(StageError, match="interrupted while writing its outputs"):
            run_case(path, out=tmp_path / "run", quiet=True, threads=1)
        monkeypatch.setattr(records.RecordTable, "write_csv", real)
        run_case(path, out=tmp_path / "run", quiet=True, threads=1, resume=True)
    finally:
        signal.signal(signal.SIGINT, old)
    a, b = _datasets(tmp_path / "ref" / "03-compact.h5"), _datasets(tmp_path / "run" / "03-compact.h5")
    assert "target porosity" in str(b["compaction/stopped"])
    assert [k for k in a if not np.array_equal(np.asarray(a[k]), np.asarray(b[k]))] == [] and sorted(a) == sorted(b)
