"""Corrupt state files (#27 items 3, 8, 12): every kind of damage ends in one clear error that
names the file (exit code 2, no traceback), from ``demcli info`` and as the input of
``demcli run --from``; a run's own corrupt output or checkpoint is computed again instead,
bit-identical to a clean run, and the log says so."""

import shutil
import struct
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.errors import StageError
from demcli.state import read_state, write_state

ROOT = Path(__file__).resolve().parents[2]
CASES = {"beads": ROOT / "cases" / "smoke" / "beads.yaml",              # spheres: pour, settle
         "ballast": ROOT / "cases" / "smoke" / "ballast_deposit.yaml"}  # polyhedra: ..., assembly, deposit
DAMAGED = {"beads": "01-settle.h5", "ballast": "03-deposit.h5"}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """Clean runs of the two smoke cases, made once."""
    out = {}
    for name, case in CASES.items():
        folder = tmp_path_factory.mktemp(name)
        run_case(case, out=folder, quiet=True)
        out[name] = folder
    return out


# --- damage to the bytes -----------------------------------------------------------------

def _truncate(fraction):
    return lambda path: path.write_bytes(path.read_bytes()[: int(path.stat().st_size * fraction)])


def _overwrite(data):
    return lambda path: path.write_bytes(data)


def _flip_at(path, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x04
    path.write_bytes(bytes(data))


def _flip_data(name, where):
    """Flip a bit at fraction ``where`` of the stored bytes of dataset ``name`` (its first
    chunk when it is deflated)."""
    def damage(path):
        with h5py.File(path) as f:
            ds = f[name]
            if ds.chunks:
                info = ds.id.get_chunk_info(0)
                offset = info.byte_offset + int(info.size * where)
            else:
                offset = ds.id.get_offset() + int(ds.id.get_storage_size() * where)
        _flip_at(path, offset)
    return damage


def _flip_meta(key):
    """Flip a bit of the float64 meta attribute ``key`` where it is stored."""
    def damage(path):
        with h5py.File(path) as f:
            value = float(f["meta"].attrs[key])
        offset = path.read_bytes().find(struct.pack("<d", value))
        assert offset > 0
        _flip_at(path, offset + 3)
    return damage


def _flip_text(text):
    """Flip a bit of the first occurrence of ``text`` in the file (an attribute's string)."""
    def damage(path):
        offset = path.read_bytes().find(text)
        assert offset > 0
        _flip_at(path, offset + 1)
    return damage


# --- damage through the state API (fresh checksums: the registry's rules must catch it) ---

def _edit(fn):
    def damage(path):
        st = read_state(path, validate=False)
        fn(st)
        write_state(path, st, validate=False)
    return damage


def _set(name, row, value):
    def fn(st):
        arr = np.array(st[name])
        arr[row] = value
        st[name] = arr
    return _edit(fn)


def _scale(name, row, factor):
    return _edit(lambda st: st[name].__setitem__(row, st[name][row] * factor))


def _replace(name, value):
    return _edit(lambda st: st.__setitem__(name, value(st)))


def _drop(name):
    return _edit(lambda st: st.groups[name.split("/")[0]].pop(name.split("/")[1]))


def _drop_group(group):
    return _edit(lambda st: st.groups.pop(group))


# --- damage with plain h5py (no checksum on what it writes) ----------------------------------

def _h5(fn):
    def damage(path):
        with h5py.File(path, "a") as f:
            fn(f)
    return damage


def _retype(name, dtype):
    def fn(f):
        data = f[name][()]
        del f[name]
        f[name] = data.astype(dtype) if dtype != "str" else np.array([str(v) for v in np.ravel(data)], dtype="S")
    return _h5(fn)


def _meta_attr(key, value):
    return _h5(lambda f: f["meta"].attrs.__setitem__(key, value))


B, P = "beads", "ballast"
CORRUPT = {
    # bytes: truncated, empty, not HDF5
    "truncated_to_1_percent": (B, _truncate(0.01)),
    "truncated_to_10_percent": (B, _truncate(0.10)),
    "truncated_to_50_percent": (B, _truncate(0.50)),
    "truncated_to_90_percent": (B, _truncate(0.90)),
    "truncated_by_one_byte": (B, lambda p: p.write_bytes(p.read_bytes()[:-1])),
    "polyhedra_truncated_to_50_percent": (P, _truncate(0.50)),
    "polyhedra_truncated_to_95_percent": (P, _truncate(0.95)),
    "empty_file": (B, _overwrite(b"")),
    "text_file": (B, _overwrite(b"name: beads\nstages: []\n")),
    "random_bytes": (B, _overwrite(np.random.default_rng(1).bytes(4096))),
    "zeros": (B, lambda p: p.write_bytes(bytes(p.stat().st_size))),
    "hdf5_signature_flipped": (B, lambda p: _flip_at(p, 1)),
    # bits flipped in the data of contiguous datasets, at several offsets
    "flip_radius_first_byte": (B, _flip_data("spheres/radius", 0.0)),
    "flip_radius_middle": (B, _flip_data("spheres/radius", 0.5)),
    "flip_radius_last_byte": (B, _flip_data("spheres/radius", 0.999)),
    "flip_positions": (B, _flip_data("bodies/x", 0.3)),
    "flip_quaternions": (B, _flip_data("bodies/q", 0.7)),
    "flip_body_ids": (B, _flip_data("bodies/id", 0.5)),
    "flip_sphere_body_index": (B, _flip_data("spheres/body", 0.5)),
    "flip_contact_force": (B, _flip_data("contacts/force", 0.5)),
    "flip_wall_normals": (B, _flip_data("walls/normal", 0.2)),
    "flip_material_density": (B, _flip_data("materials/density", 0.5)),
    "flip_energy_scalar": (B, _flip_data("energy/damping", 0.5)),
    "flip_record_column": (B, _flip_data("records/dem/time", 0.5)),
    "flip_deflated_chunk": (P, _flip_data("polyhedron_shapes/vertices", 0.5)),
    "flip_deflated_chunk_start": (P, _flip_data("polyhedron_shapes/face_normal", 0.05)),
    "flip_polyhedra_volume": (P, _flip_data("polyhedron_shapes/volume", 0.5)),
    # bits flipped in attributes (HDF5 keeps no checksum of them)
    "flip_meta_time": (B, _flip_meta("time")),
    "flip_meta_dt": (B, _flip_meta("dt")),
    "flip_rng_state": (B, _flip_text(b'"bit_generator"')),
    "flip_record_units": (B, _flip_text(b"box.x0.position")),
    # item 3: values that break the registry's rules
    "zero_radius": (B, _set("spheres/radius", 3, 0.0)),
    "negative_radius": (B, _set("spheres/radius", 0, -1e-3)),
    "nan_radius": (B, _set("spheres/radius", 7, np.nan)),
    "zero_mass": (B, _set("bodies/mass", 2, 0.0)),
    "negative_mass": (B, _set("bodies/mass", 149, -0.01)),
    "zero_inertia": (B, _set("bodies/inertia", 5, [0.0, 1e-9, 1e-9])),
    "nan_position": (B, _set("bodies/x", 10, [np.nan, 0.0, 0.0])),
    "inf_position": (B, _set("bodies/x", 11, [0.0, np.inf, 0.0])),
    "inf_velocity": (B, _set("bodies/v", 12, [0.0, 0.0, -np.inf])),
    "nan_angular_velocity": (B, _set("bodies/omega", 13, [np.nan] * 3)),
    "nan_contact_force": (B, _set("contacts/force", 0, [np.nan, 0.0, 0.0])),
    "nan_quaternion": (B, _set("bodies/q", 1, [np.nan, 0.0, 0.0, 0.0])),
    "non_unit_quaternion": (B, _scale("bodies/q", 4, 1.001)),
    "zero_quaternion": (B, _set("bodies/q", 6, [0.0, 0.0, 0.0, 0.0])),
    "non_unit_wall_normal": (B, _scale("walls/normal", 2, 0.5)),
    "duplicate_body_ids": (B, _edit(lambda st: st["bodies/id"].__setitem__(9, st["bodies/id"][3]))),
    "sphere_body_out_of_range": (B, _set("spheres/body", 0, 150)),
    "sphere_body_negative": (B, _set("spheres/body", 1, -1)),
    "sphere_material_out_of_range": (B, _set("spheres/material", 2, 2)),
    "contact_index_out_of_range": (B, _set("contacts/j", 0, 1000)),
    "wall_material_out_of_range": (B, _set("walls/material", 0, 5)),
    "zero_density": (B, _set("materials/density", 0, 0.0)),
    "negative_young": (B, _set("materials/young", 1, -2e11)),
    "polyhedra_shape_out_of_range": (P, _set("polyhedra/shape", 0, 10_000)),
    "polyhedra_zero_volume": (P, _set("polyhedron_shapes/volume", 4, 0.0)),
    "polyhedra_nan_vertex": (P, _set("polyhedron_shapes/vertices", 8, [np.nan, 0.0, 0.0])),
    "polyhedra_non_unit_face_normal": (P, _scale("polyhedron_shapes/face_normal", 3, 1.1)),
    "polyhedra_face_vertex_out_of_range": (P, _set("polyhedron_shapes/face_vertices", 0, 99_999)),
    "polyhedra_wall_contact_body_out_of_range": (P, _set("body_wall_contacts/body", 0, 143)),
    "polyhedra_nan_wall_contact_depth": (P, _set("body_wall_contacts/depth", 0, np.nan)),
    # item 8 and structure: shapes, dtypes, missing and extra parts
    "scalar_for_radius_array": (B, _replace("spheres/radius", lambda st: np.float64(1e-3))),
    "scalar_for_positions": (B, _replace("bodies/x", lambda st: np.float64(0.0))),
    "vector_for_positions": (B, _replace("bodies/x", lambda st: st["bodies/x"][:, 0].copy())),
    "quaternions_of_three": (B, _replace("bodies/q", lambda st: st["bodies/q"][:, :3].copy())),
    "mass_one_row_short": (B, _replace("bodies/mass", lambda st: st["bodies/mass"][:-1].copy())),
    "positions_as_int": (B, _retype("bodies/x", np.int64)),
    "positions_as_float32": (B, _retype("bodies/x", np.float32)),
    "flags_as_int64": (B, _retype("bodies/flags", np.int64)),
    "radius_as_strings": (B, _retype("spheres/radius", "str")),
    "sphere_body_as_float": (B, _retype("spheres/body", np.float64)),
    "missing_positions": (B, _drop("bodies/x")),
    "missing_radius": (B, _drop("spheres/radius")),
    "missing_material_density": (B, _drop("materials/density")),
    "missing_contact_force": (B, _drop("contacts/force")),
    "missing_group_bodies": (B, _drop_group("bodies")),
    "missing_group_spheres": (B, _drop_group("spheres")),
    "missing_group_materials": (B, _drop_group("materials")),
    "missing_group_meta": (B, _h5(lambda f: f.__delitem__("meta"))),
    "extra_garbage_group": (B, _replace("garbage/data", lambda st: np.random.default_rng(2).normal(size=17))),
    "extra_dataset_in_bodies": (B, _replace("bodies/garbage", lambda st: np.zeros(150))),
    "stray_top_level_dataset": (B, _h5(lambda f: f.create_dataset("junk", data=np.arange(3)))),
    "schema_version_0": (B, _meta_attr("schema_version", np.int64(0))),
    "schema_version_99": (B, _meta_attr("schema_version", np.int64(99))),
    "schema_version_text": (B, _meta_attr("schema_version", "one")),
    "meta_dt_removed": (B, _h5(lambda f: f["meta"].attrs.__delitem__("dt"))),
}


def _assert_clean_error(result, path):
    """Exit 2 with 'Error: ...' naming the file, through click (SystemExit), no traceback."""
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Error" in result.output and str(path) in result.output, result.output
    assert "Traceback" not in result.output, result.output


def test_there_are_many_corruptions():
    assert len(CORRUPT) >= 50


@pytest.mark.parametrize("name", list(CORRUPT))
def test_info_on_a_corrupt_state_is_a_clear_error(clean, tmp_path, name):
    # Given a copy of a clean state, damaged
    source, damage = CORRUPT[name]
    path = tmp_path / f"{name}.h5"
    shutil.copy(clean[source] / DAMAGED[source], path)
    damage(path)
    # When summarised / Then exit 2 and one error naming the file
    _assert_clean_error(CliRunner().invoke(cli, ["info", str(path)]), path)


RUN_INPUTS = ["truncated_to_50_percent", "empty_file", "text_file", "flip_radius_middle", "flip_positions",
              "flip_meta_time", "zero_radius", "negative_mass", "nan_position", "non_unit_quaternion",
              "duplicate_body_ids", "sphere_body_out_of_range", "scalar_for_radius_array", "positions_as_int",
              "missing_group_bodies", "extra_garbage_group", "schema_version_99"]


@pytest.mark.parametrize("name", RUN_INPUTS)
def test_a_corrupt_input_state_stops_the_run(clean, tmp_path, name):
    # Given a finished run whose first state (the input of settle) is damaged
    run = tmp_path / "run"
    shutil.copytree(clean["beads"], run)
    before = (run / "01-settle.h5").read_bytes()
    CORRUPT[name][1](run / "00-pour.h5")
    # When settle is run again from it
    result = CliRunner().invoke(cli, ["run", str(CASES["beads"]), "--from", "settle", "--out", str(run), "--quiet"])
    # Then exit 2 naming the input (the user's file is not recomputed), settle's state untouched
    _assert_clean_error(result, run / "00-pour.h5")
    assert (run / "01-settle.h5").read_bytes() == before


# --- item 12: a run's own outputs are computed again ----------------------------------------

@pytest.mark.parametrize("damaged, name, recomputed", [
    ("01-settle.h5", "flip_radius_middle", ["settle"]),
    ("01-settle.h5", "truncated_to_50_percent", ["settle"]),
    ("01-settle.h5", "flip_meta_time", ["settle"]),
    ("01-settle.h5", "zero_radius", ["settle"]),
    ("00-pour.h5", "flip_positions", ["pour"]),  # settle's input is the same again: skipped
])
def test_a_corrupt_stage_output_is_recomputed(clean, tmp_path, h5_differences, damaged, name, recomputed):
    # Given a finished run with one of its states damaged
    run = tmp_path / "run"
    shutil.copytree(clean["beads"], run)
    CORRUPT[name][1](run / damaged)
    # When the case is run again
    results = run_case(CASES["beads"], out=run, quiet=True)
    # Then the damaged stage is computed again (and only it), bit-identical to the clean run
    assert [r.name for r in results if not r.skipped] == recomputed
    for state in ("00-pour.h5", "01-settle.h5"):
        assert h5_differences(clean["beads"] / state, run / state) == []
        assert (clean["beads"] / state).read_bytes() == (run / state).read_bytes()
    # and the log says why
    log = (run / "log.txt").read_text()
    assert f"[{recomputed[0]}] state {damaged} is unreadable (" in log and "); recomputing the stage" in log


@pytest.mark.parametrize("name", ["flip_positions", "truncated_to_90_percent", "nan_position"])
def test_a_corrupt_checkpoint_starts_the_stage_afresh(clean, tmp_path, monkeypatch, h5_differences, name):
    from demcli.engine.system import System

    # Given settle interrupted at step 1500, its checkpoint then damaged
    run = tmp_path / "run"
    real = System.advance

    def interrupted(self, n):
        if self.step >= 1500:
            raise KeyboardInterrupt
        return real(self, n)

    monkeypatch.setattr(System, "advance", interrupted)
    with pytest.raises(StageError, match="interrupted"):
        run_case(CASES["beads"], out=run, quiet=True)
    monkeypatch.setattr(System, "advance", real)
    checkpoint = run / "01-settle.ckpt.h5"
    CORRUPT[name][1](checkpoint)
    # When resumed
    run_case(CASES["beads"], out=run, quiet=True, resume=True)
    # Then the stage ran from its start: bit-identical to the clean run, checkpoint gone
    assert h5_differences(clean["beads"] / "01-settle.h5", run / "01-settle.h5") == []
    assert (clean["beads"] / "01-settle.h5").read_bytes() == (run / "01-settle.h5").read_bytes()
    assert not checkpoint.exists()
    # and the log says so
    log = (run / "log.txt").read_text()
    assert "[settle] checkpoint 01-settle.ckpt.h5 is unreadable (" in log
    assert "); starting the stage afresh" in log and "resuming from" not in log
