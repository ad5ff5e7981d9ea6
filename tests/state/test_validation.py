"""States are validated when read (#27 items 3, 8, 12): value rules of the registry, dtypes and
shapes of the datasets on disk, and the checksums of datasets and attributes."""

import struct

import h5py
import numpy as np
import pytest

from demcli.errors import StateError
from demcli.state import check, read_meta, read_state, summarize, write_state
from demcli.state.fields import FIELDS, example_state
from demcli.state.h5 import ATTRS_CRC_ATTR, CRC_ATTR
from demcli.state.rules import UNIT_TOL


@pytest.fixture
def state():
    return example_state(rolling=True)


def _read_error(tmp_path, state, checked=True):
    """The message read_state gives for ``state`` once written (``checked``: by write_state's
    structure check, which leaves the values to the reader; else unchecked)."""
    path = write_state(tmp_path / "bad.h5", state, validate=checked)
    with pytest.raises(StateError) as err:
        read_state(path)
    text = err.value.format_message()
    assert text.startswith(f"{path}: ") and "\n" not in text
    return text


# --- item 3: value rules --------------------------------------------------------------

@pytest.mark.parametrize("path, row, value, rule, shown", [
    ("spheres/radius", 2, 0.0, "> 0", "row 2 holds 0"),
    ("spheres/radius", 5, -0.003, "> 0", "row 5 holds -0.003"),
    ("bodies/mass", 1, -0.01, "> 0", "row 1 holds -0.01"),
    ("bodies/inertia", 3, [1e-7, 0.0, 1e-7], "> 0", "row 3 holds [1e-07, 0, 1e-07]"),
    ("materials/density", 0, 0.0, "> 0", "row 0 holds 0"),
    ("bodies/x", 2, [0.05, np.nan, 0.05], "finite", "row 2 holds [0.05, nan, 0.05]"),
    ("bodies/v", 0, [np.inf, 0.0, 0.0], "finite", "row 0 holds [inf, 0, 0]"),
    ("spheres/offset", 4, [0.0, 0.0, -np.inf], "finite", "row 4 holds [0, 0, -inf]"),
    ("contacts/force", 1, [np.nan, 0.0, 0.0], "finite", "row 1 holds [nan, 0, 0]"),
    ("walls/normal", 1, [2.0, 0.0, 0.0], "a unit vector", "row 1 holds [2, 0, 0] (norm 2)"),
])
def test_a_value_rule_broken_names_file_field_rule_row_and_value(tmp_path, state, path, row, value, rule, shown):
    # Given a state with one bad value (written: the writer keeps a stage's result)
    state[path][row] = value
    # When read / Then the file, the field, the rule, the row and its value are named
    text = _read_error(tmp_path, state)
    assert f"field {path!r} must be {rule}" in text and shown in text


def test_zero_radius_state_is_refused_by_demcli_info(tmp_path, state):
    # Given a state with a zero sphere radius (before: info said "validation ok", run went on with dt <= 0)
    state["spheres/radius"][0] = 0.0
    path = write_state(tmp_path / "zero.h5", state)
    # When summarised / Then StateError names it
    with pytest.raises(StateError, match=r"spheres/radius' must be > 0: row 0 holds 0"):
        summarize(path)


def test_quaternion_norm_tolerance(tmp_path, state):
    # Given a quaternion off unit length by a tenth of the tolerance, and one by ten times it
    q = state["bodies/q"]
    q[0] *= 1 + UNIT_TOL / 10
    assert read_state(write_state(tmp_path / "ok.h5", state)) == state
    q[1] *= 1 + UNIT_TOL * 10
    # Then only the second is refused, with its norm
    text = _read_error(tmp_path, state)
    assert "'bodies/q' must be a unit vector" in text and "row 1 holds" in text and "norm 1.00001" in text
    assert "row 0" not in text


def test_duplicate_body_ids_name_both_rows(tmp_path, state):
    state["bodies/id"][3] = state["bodies/id"][1]
    text = _read_error(tmp_path, state)
    assert "field 'bodies/id' must be unique: rows 1 and 3 both hold 101" in text


@pytest.mark.parametrize("path, value, needle", [
    ("spheres/body", 4, "'spheres/body' must be in [0, n_b=4): row 0 holds 4"),
    ("spheres/body", -1, "'spheres/body' must be in [0, n_b=4): row 0 holds -1"),
    ("spheres/material", 2, "'spheres/material' must be in [0, n_m=2): row 0 holds 2"),
    ("contacts/j", 12, "'contacts/j' must be in [0, n_s=12): row 0 holds 12"),
    ("wall_contacts/wall", 3, "'wall_contacts/wall' must be in [0, n_w=3): row 0 holds 3"),
])
def test_index_out_of_range(tmp_path, state, path, value, needle):
    # Given an index out of range (refused by write_state too: written here without its check)
    state[path][0] = value
    assert needle in _read_error(tmp_path, state, checked=False)


def test_index_into_a_group_the_state_lacks(tmp_path, state):
    # Given sphere-wall contacts but no walls (a dim no field has is of size 0)
    del state.groups["walls"]
    assert "'wall_contacts/wall' must be in [0, n_w=0): row 0 holds 0" in _read_error(tmp_path, state, checked=False)


def test_several_bad_rows_are_counted(tmp_path, state):
    state["spheres/radius"][[1, 4, 7]] = -1.0
    assert "row 1 holds -1; 3 of 12 rows break it" in _read_error(tmp_path, state)


def test_legitimate_nan_and_empty_arrays_pass(tmp_path, state):
    # Given NaN where the registry allows it (a record column, a field without the finite rule)
    # and empty contact arrays
    state["records/energy/kinetic"][2] = np.nan
    state["energy/kinetic"] = np.float64(np.nan)
    state.groups["contacts"] = {"i": np.zeros(0, np.int64), "j": np.zeros(0, np.int64),
                                "ft": np.zeros((0, 3)), "mr": np.zeros((0, 3)), "force": np.zeros((0, 3))}
    # When read / Then it is valid
    assert read_state(write_state(tmp_path / "s.h5", state)) == state


def test_the_rules_are_declared_in_the_registry():
    # Given the core fields / Then the rules sit on them, shown in docs/state.md's rules column
    assert FIELDS["spheres/radius"].rules_text == "finite, > 0"
    assert FIELDS["bodies/q"].rules_text == "finite, unit rows"
    assert FIELDS["bodies/id"].rules_text == "unique"
    assert FIELDS["spheres/body"].rules_text == "< n_b"


def test_value_rules_are_left_out_of_the_write_check(state):
    # Given a bad value / Then the structure check of a write passes, the full check does not
    state["bodies/mass"][0] = 0.0
    assert check(state, values=False) == []
    assert any("'bodies/mass' must be > 0" in p for p in check(state))


def test_a_large_valid_state_passes_every_rule():
    # Given 300 000 single-sphere bodies (the cost is measured in the note, not here:
    # speed belongs in benchmarks) / When checked / Then no rule refuses it
    big = example_state(n_bodies=300_000, spheres_per_body=1, walls=False, contacts=False)
    assert check(big) == []


# --- item 8: dtype, rank and shape of what is on disk ----------------------------------

def _replace_dataset(path, name, data):
    """Put ``data`` in place of dataset ``name`` with plain h5py (no checksum: unverified)."""
    with h5py.File(path, "a") as f:
        del f[name]
        f[name] = data


@pytest.mark.parametrize("name, data, needle", [
    ("spheres/radius", np.float64(0.004), "field 'spheres/radius' has shape (), expected (n_s)"),
    ("bodies/x", np.zeros(4), "field 'bodies/x' has shape (4,), expected (n_b, 3)"),
    ("bodies/q", np.zeros((4, 3)), "field 'bodies/q' has shape (4, 3), expected (n_b, 4)"),
    ("bodies/x", np.zeros((4, 3), np.int64), "field 'bodies/x' has dtype int64, expected float"),
    ("bodies/x", np.zeros((4, 3), np.float32), "field 'bodies/x' is stored as float32, expected float64"),
    ("bodies/flags", np.zeros(4, np.int64), "field 'bodies/flags' is stored as int64, expected int8"),
    ("bodies/mass", np.ones(3), "inconsistent n_b: 'bodies/mass' has 3"),
])
def test_dtype_and_shape_are_checked_on_read(tmp_path, state, name, data, needle):
    path = write_state(tmp_path / "s.h5", state)
    _replace_dataset(path, name, data)
    with pytest.raises(StateError) as err:
        read_state(path)
    assert str(path) in err.value.format_message() and needle in err.value.format_message()
    # and demcli info says the same instead of a TypeError
    with pytest.raises(StateError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        summarize(path)


# --- item 12: checksums ----------------------------------------------------------------

def _flip(path, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x01
    path.write_bytes(bytes(data))


def test_every_dataset_and_attribute_group_carries_a_checksum(tmp_path, state):
    path = write_state(tmp_path / "s.h5", state)
    with h5py.File(path) as f:
        datasets, groups = [], []
        f.visititems(lambda n, o: (datasets if isinstance(o, h5py.Dataset) else groups).append(o))
        assert datasets and all(CRC_ATTR in ds.attrs for ds in datasets)
        assert ATTRS_CRC_ATTR in f["meta"].attrs and ATTRS_CRC_ATTR in f["rng"].attrs
    # and the checksums are invisible in the State read back
    back = read_state(path)
    assert ATTRS_CRC_ATTR not in back.meta and ATTRS_CRC_ATTR not in back.group_attrs["rng"]
    assert ATTRS_CRC_ATTR not in read_meta(path)


@pytest.mark.parametrize("name", ["spheres/radius", "bodies/id", "materials/name", "energy/kinetic"])
def test_a_flipped_bit_in_a_contiguous_dataset_is_found(tmp_path, state, name):
    # Given a bit flipped in the raw bytes of a small (contiguous, unfiltered) dataset
    path = write_state(tmp_path / "s.h5", state)
    with h5py.File(path) as f:
        offset = f[name].id.get_offset()
    _flip(path, offset + 1)
    # When read / Then the dataset and the checksum mismatch are named
    with pytest.raises(StateError) as err:
        read_state(path)
    assert f"{path}: dataset {name}" in err.value.format_message()
    assert "checksum mismatch" in err.value.format_message() or "cannot be read" in err.value.format_message()


def test_a_flipped_bit_in_a_deflated_dataset_is_found(tmp_path):
    # Given a bit flipped in the middle of a gzip chunk of a large dataset
    path = write_state(tmp_path / "s.h5", example_state(n_bodies=3000, spheres_per_body=1))
    with h5py.File(path) as f:
        info = f["bodies/x"].id.get_chunk_info(0)
    _flip(path, info.byte_offset + info.size // 2)
    with pytest.raises(StateError, match=r"dataset bodies/x (cannot be read|: checksum mismatch)"):
        read_state(path)


def test_a_flipped_bit_in_a_meta_attribute_is_found(tmp_path, state):
    # Given the stored time changed by one bit (HDF5 keeps no checksum of attributes)
    path = write_state(tmp_path / "s.h5", state)
    offset = path.read_bytes().find(struct.pack("<d", state.meta["time"]))
    assert offset > 0
    _flip(path, offset)
    # When read, also the meta only / Then the attributes of /meta are named
    for read in (read_state, read_meta):
        with pytest.raises(StateError, match=r"attributes of /meta: checksum mismatch"):
            read(path)


def test_a_file_without_checksums_still_reads(tmp_path, state):
    # Given a file of an earlier demcli: no checksum attributes
    path = write_state(tmp_path / "s.h5", state)
    with h5py.File(path, "a") as f:
        f.visititems(lambda n, o: o.attrs.__delitem__(CRC_ATTR) if CRC_ATTR in o.attrs else None)
        for grp in (f["meta"], f["rng"], f["records/energy"]):
            del grp.attrs[ATTRS_CRC_ATTR]
    # When read / Then it is the same state (unverified, but validated)
    assert read_state(path) == state
