"""3D asphalt (seed 000): cutting a cylinder or prism specimen from the compacted aggregates."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from demcli import run_case
from demcli.errors import InputError
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"
SMOKE = CASES / "smoke" / "asphalt_carved_cube.yaml"


def _recut(smoke_run, tmp_path, overrides):
    """Re-run only the cut stage of the smoke case, on a copy of its states, with overrides."""
    out = tmp_path / "run"
    out.mkdir()
    for f in smoke_run.glob("0[0-3]-*.h5"):
        shutil.copy(f, out / f.name)
    run_case(SMOKE, out=out, quiet=True, threads=1, only="cut", overrides=overrides)
    return read_state(out / "04-cut.h5"), read_state(out / "03-compact.h5")


def _radial(st):
    c = st.sphere_centres() - st["specimen/centre"]
    return np.hypot(c[:, 0], c[:, 1]), np.abs(c[:, 2]), st["spheres/radius"]


def test_trimmed_specimen_lies_inside_the_cylinder(smoke_run):
    from demcli.geometry.carving import element_volume
    from demcli.stages.asphalt.common import plane_violations

    st = read_state(smoke_run / "04-cut.h5")
    before = read_state(smoke_run / "03-compact.h5")
    d, h = st["specimen/size"][0], st["specimen/size"][2]
    rho, z, r = _radial(st)
    # Then every ball lies wholly inside the 15 x 15 mm cylinder
    assert np.all(rho + r <= d / 2 + 1e-12) and np.all(z + r <= h / 2 + 1e-12)
    assert st["specimen/volume"] == pytest.approx(np.pi / 4 * d * d * h)
    # and crossing aggregates were trimmed: fewer balls than their clumps had, mass from what is left
    table = st.groups["records/cut"]
    assert table["trimmed"][0] > 0 and table["balls_kept"][0] < table["balls_in"][0]
    a = 2 * float(st["aggregates/ball_radius"])
    count = np.bincount(st["spheres/body"])
    assert np.allclose(st["bodies/mass"], count * 2650.0 * element_volume(a, "cells"), rtol=1e-12)
    assert np.allclose(st["aggregates/volume"], count * a ** 3, rtol=1e-12)
    # and rebuilt clumps keep their members where they were, in principal frames, inside their planes
    seeds = st["aggregates/seed"]
    old_body = {int(s): k for k, s in enumerate(before["aggregates/seed"])}
    c_old = before.sphere_centres()
    for k in range(len(seeds)):
        mine = st.sphere_centres()[st["spheres/body"] == k]
        theirs = c_old[before["spheres/body"] == old_body[int(seeds[k])]]
        dist = np.min(np.linalg.norm(mine[:, None] - theirs[None], axis=-1), axis=1)
        assert dist.max() < 1e-9
    assert plane_violations(st) <= 1e-9 * a
    # and contacts between kept spheres keep their history, remapped
    if "contacts/i" in st and len(st["contacts/i"]):
        assert st["contacts/i"].max() < len(r) and np.all(st["contacts/i"] < st["contacts/j"])
    # and the skeleton porosity is that of the member cells inside the cylinder
    assert st["specimen/porosity"] == pytest.approx(1 - len(r) * a ** 3 / st["specimen/volume"], rel=1e-12)


def test_keep_mode_keeps_crossing_aggregates_whole(smoke_run, tmp_path):
    st, before = _recut(smoke_run, tmp_path, ["stages.cut.crossing=keep"])
    # Then the kept aggregates have all their balls (those crossing the surface stick out)
    seeds_before = {int(s): k for k, s in enumerate(before["aggregates/seed"])}
    n_before = np.bincount(before["spheres/body"])
    n_after = np.bincount(st["spheres/body"])
    for k, s in enumerate(st["aggregates/seed"]):
        assert n_after[k] == n_before[seeds_before[int(s)]]
    assert np.allclose(st["bodies/mass"], before["bodies/mass"][[seeds_before[int(s)] for s in st["aggregates/seed"]]])
    # and their centres of mass lie inside, while some balls lie outside
    rho, z, r = _radial(st)
    x = st["bodies/x"] - st["specimen/centre"]
    d, h = st["specimen/size"][0], st["specimen/size"][2]
    assert np.all(np.hypot(x[:, 0], x[:, 1]) <= d / 2) and np.all(np.abs(x[:, 2]) <= h / 2)
    assert np.any(rho + r > d / 2) or np.any(z + r > h / 2)


def test_drop_mode_and_prisms(smoke_run, tmp_path):
    st, _ = _recut(smoke_run, tmp_path, ["stages.cut.crossing=drop",
                                         "stages.cut.shape={shape: prism, size: [14 mm, 12 mm, 10 mm]}"])
    # Then only aggregates wholly inside the prism remain
    c = st.sphere_centres() - st["specimen/centre"]
    r = st["spheres/radius"][:, None]
    assert np.all(np.abs(c) + r <= np.array([7e-3, 6e-3, 5e-3]) + 1e-12)
    assert st["specimen/volume"] == pytest.approx(14e-3 * 12e-3 * 10e-3)


def test_a_specimen_larger_than_the_compacted_box_is_refused(smoke_run, tmp_path):
    with pytest.raises(InputError, match="does not fit the walls' box"):
        _recut(smoke_run, tmp_path, ["stages.cut.shape={shape: cylinder, diameter: 101.6 mm, height: 63.5 mm}"])
