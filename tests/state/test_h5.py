"""HDF5 state files: round trip, determinism, and every class of bad file."""

import time

import h5py
import numpy as np
import pytest

from demcli.errors import StateError
from demcli.state import read_meta, read_state, state_hash, summarize, write_state
from demcli.state.fields import example_state


@pytest.fixture
def state():
    return example_state(rolling=True)


@pytest.fixture
def good_file(tmp_path, state):
    return write_state(tmp_path / "good.h5", state)


def test_round_trip_equal(tmp_path, state):
    # Given a fully populated state (strings, int8 flags, scalars, records, rng)
    # When it is written and read back
    back = read_state(write_state(tmp_path / "s.h5", state))
    # Then every dataset (dtype, shape, values), meta and attribute is equal
    assert back == state
    assert back["bodies/flags"].dtype == np.int8
    assert list(back["materials/name"]) == ["granite", "mastic"]
    assert back.meta["effects"] == state.meta["effects"]
    assert isinstance(back.meta["step"], int) and isinstance(back.meta["time"], float)


def test_round_trip_empty_contacts(tmp_path, state):
    # Given a state with zero contacts (a dilute start)
    state.groups["contacts"] = {"i": np.zeros(0, np.int64), "j": np.zeros(0, np.int64),
                                "ft": np.zeros((0, 3)), "mr": np.zeros((0, 3)), "force": np.zeros((0, 3))}
    # When written and read / Then the empty arrays keep their shapes
    back = read_state(write_state(tmp_path / "s.h5", state))
    assert back["contacts/ft"].shape == (0, 3) and back == state


def test_two_writes_are_byte_identical(tmp_path, state):
    # Given the same state written twice, a moment apart, and once more after a read
    a = write_state(tmp_path / "a.h5", state)
    time.sleep(1.1)
    b = write_state(tmp_path / "b.h5", state)
    c = write_state(tmp_path / "c.h5", read_state(a))
    # Then the files are byte-identical (no timestamps, fixed order)
    assert a.read_bytes() == b.read_bytes() == c.read_bytes()


def test_large_datasets_are_stored_deflated_and_read_back_exactly(tmp_path):
    from demcli.state.h5 import COMPRESS_MIN_BYTES

    # Given a state of 3000 bodies: 72 kB per (n_b, 3) float array, above the threshold
    big = example_state(n_bodies=3000, spheres_per_body=1)
    assert big["bodies/x"].nbytes >= COMPRESS_MIN_BYTES > big["bodies/mass"].nbytes
    # When written twice
    a, b = write_state(tmp_path / "a.h5", big), write_state(tmp_path / "b.h5", big)
    # Then the large numeric datasets are deflated, the small ones contiguous, the files identical
    with h5py.File(a) as f:
        assert f["bodies/x"].compression == "gzip" and f["bodies/x"].shuffle
        assert f["bodies/mass"].compression is None and f["bodies/mass"].chunks is None
        assert np.array_equal(f["bodies/x"][()], big["bodies/x"])  # plain h5py reads them
    assert a.read_bytes() == b.read_bytes()
    # and the state reads back equal, bit for bit
    assert read_state(a) == big


def test_state_hash_ignores_provenance_and_tracks_data(tmp_path, state):
    # Given a state and its copy read back from disk
    h = state_hash(state)
    assert state_hash(read_state(write_state(tmp_path / "s.h5", state))) == h
    # When only provenance changes, the hash stays
    other = state.copy()
    other.meta["stage"] = "renamed"
    other.meta["created_by"] = "someone else"
    other.meta["machine"] = "another CPU (numba target other); numpy 0"
    assert state_hash(other) == h
    # When one coordinate moves by one ulp, the hash changes
    other["bodies/x"][0, 0] = np.nextafter(other["bodies/x"][0, 0], 1.0)
    assert state_hash(other) != h


def test_a_state_names_the_machine_that_computed_it(tmp_path, state):
    # Given a new state and the machine's own description
    import llvmlite.binding as llvm
    import numba

    from demcli.state.fields import new_state

    meta = new_state("settle", "dem").meta
    # Then it names the CPU numba compiles for and the numerical libraries' versions
    assert f"numba target {llvm.get_host_cpu_name()}" in meta["machine"]
    assert f"numba {numba.__version__}" in meta["machine"] and f"numpy {np.__version__}" in meta["machine"]
    # and keeps it through a file; a file written without it (older demcli) still reads
    back = read_state(write_state(tmp_path / "s.h5", state))
    assert back.meta["machine"] == state.meta["machine"]
    del state.meta["machine"]
    assert "machine" not in read_state(write_state(tmp_path / "old.h5", state)).meta


def test_int32_input_is_stored_as_int64_and_hashes_alike(tmp_path, state):
    # Given sphere indices handed over as int32
    narrow = state.copy()
    narrow["spheres/body"] = narrow["spheres/body"].astype(np.int32)
    # When written and read / Then they come back as the registry's int64, same hash
    back = read_state(write_state(tmp_path / "s.h5", narrow))
    assert back["spheres/body"].dtype == np.int64
    assert state_hash(narrow) == state_hash(back) == state_hash(state)


def _msg(exc_info):
    return exc_info.value.format_message()


def test_missing_file(tmp_path):
    path = tmp_path / "nope.h5"
    with pytest.raises(StateError) as err:
        read_state(path)
    assert _msg(err) == f"{path}: no such state file"


def test_text_file_is_not_hdf5(tmp_path):
    # Given a YAML file passed where a state is expected
    path = tmp_path / "case.h5"
    path.write_text("stages:\n  - compaction\n")
    with pytest.raises(StateError) as err:
        read_state(path)
    # Then the message names the file and says what it looks like, on one line
    assert str(path) in _msg(err) and "not an HDF5" in _msg(err) and "text" in _msg(err)
    assert "\n" not in _msg(err)


def test_empty_file(tmp_path):
    path = tmp_path / "empty.h5"
    path.write_bytes(b"")
    with pytest.raises(StateError, match="empty"):
        read_state(path)


def test_truncated_file(tmp_path, good_file):
    # Given a real state file cut in half (a crash during a non-atomic copy)
    data = good_file.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    # When read
    with pytest.raises(StateError) as err:
        read_state(cut)
    # Then a one-line message names the file and says truncated or corrupt
    assert _msg(err).startswith(f"{cut}: ") and "truncated or corrupt" in _msg(err)
    assert "\n" not in _msg(err)


def test_foreign_hdf5(tmp_path):
    # Given an HDF5 file from another program
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f["particles/x"] = np.zeros((3, 3))
    with pytest.raises(StateError) as err:
        read_state(path)
    assert str(path) in _msg(err) and "not a demcli state file" in _msg(err) and "particles" in _msg(err)


def test_newer_schema_version(tmp_path, good_file):
    # Given a file claiming a schema version from the future
    with h5py.File(good_file, "a") as f:
        f["meta"].attrs["schema_version"] = np.int64(2)
    with pytest.raises(StateError) as err:
        read_state(good_file)
    assert str(good_file) in _msg(err) and "newer demcli" in _msg(err) and "schema_version 2" in _msg(err)
    # And read_meta refuses it the same way
    with pytest.raises(StateError, match="newer demcli"):
        read_meta(good_file)


def test_older_unsupported_schema_version(tmp_path, good_file):
    with h5py.File(good_file, "a") as f:
        f["meta"].attrs["schema_version"] = np.int64(0)
    with pytest.raises(StateError, match="schema_version 0 is not supported"):
        read_state(good_file)


def test_missing_required_field_in_file(tmp_path, good_file):
    # Given a file whose contacts lost their tangential history
    with h5py.File(good_file, "a") as f:
        del f["contacts/force"]
    # When read / Then the file, the field and its writer are named
    with pytest.raises(StateError) as err:
        read_state(good_file)
    assert str(good_file) in _msg(err) and "contacts/force" in _msg(err) and "written by engine" in _msg(err)
    # And without validation the rest is still readable
    assert "contacts/i" in read_state(good_file, validate=False)


def test_invalid_state_is_not_written(tmp_path, state):
    # Given an invalid state
    state["bodies/mass"] = state["bodies/mass"][:2]
    path = tmp_path / "bad.h5"
    # When writing / Then StateError and no file (and no temp file) appear
    with pytest.raises(StateError, match="not written"):
        write_state(path, state)
    assert list(tmp_path.iterdir()) == []


def test_read_meta_and_summary(good_file, state):
    # Given a good file
    meta = read_meta(good_file)
    assert meta["step"] == state.meta["step"] and meta["effects"] == state.meta["effects"]
    # When summarized
    text = summarize(good_file)
    # Then the summary has stage, counts, time, energy, records, extent, radius
    for expected in ("stage      demo (compaction)", f"machine    {state.meta['machine']}", "4 bodies",
                     "12 spheres", "11 contacts",
                     "step 250", "kinetic", "energy: 6 rows (time, kinetic, step)",
                     "extent", "radius     mean", "validation ok"):
        assert expected in text, expected


def test_summary_refuses_an_invalid_state(good_file):
    # Given a file that lost bodies/mass
    with h5py.File(good_file, "a") as f:
        del f["bodies/mass"]
    # When summarized / Then a StateError names the file and the field (demcli info exits 2)
    with pytest.raises(StateError) as err:
        summarize(good_file)
    assert str(good_file) in _msg(err) and "missing field 'bodies/mass'" in _msg(err)
