"""3D asphalt (seed 000): mastic balls in the voids, and contact models by phase pair."""

import shutil
from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml

from demcli import run_case
from demcli.errors import ConfigError, StageError, StateError
from demcli.state import read_state

CASES = Path(__file__).resolve().parents[2] / "cases"
SMOKE = CASES / "smoke" / "asphalt_carved_cube.yaml"


def _remastic(smoke_run, tmp_path, overrides):
    out = tmp_path / "run"
    out.mkdir()
    for f in smoke_run.glob("0[0-4]-*.h5"):
        shutil.copy(f, out / f.name)
    run_case(SMOKE, out=out, quiet=True, threads=1, only="mastic", overrides=overrides)
    return read_state(out / "05-mastic.h5")


def test_air_voids_within_one_ball_of_the_target(smoke_run):
    from demcli.stages.asphalt.common import inside_member_cells
    from demcli.stages.asphalt.cut import inside

    st = read_state(smoke_run / "05-mastic.h5")
    m = st.groups["mastic"]
    cells = int(m["cells"])
    # Then air voids = (void cells - mastic balls) / cells, within one ball of the 4 % target
    assert abs(float(m["air_voids"]) - 0.04) <= 1.0 / cells
    assert float(m["air_voids"]) == pytest.approx((int(m["void_cells"]) - int(m["count"])) / cells, rel=1e-12)
    # and the mastic mass is count x density x cell volume
    r = float(m["ball_radius"])
    assert float(m["mass"]) == pytest.approx(int(m["count"]) * 2000.0 * (2 * r) ** 3, rel=1e-12)
    # and the mastic balls are single-ball bodies after the aggregates, in the voids and the specimen
    phase = st["phases/sphere"]
    n_agg = len(st["aggregates/body"])
    assert np.all(phase[st["spheres/body"] < n_agg] == 0) and np.all(phase[st["spheres/body"] >= n_agg] == 1)
    centres = st.sphere_centres()[phase == 1]
    assert len(centres) == int(m["count"]) and np.all(st["spheres/radius"][phase == 1] == r)
    assert not inside_member_cells(st, centres).any()
    assert inside(centres, 0.0, "cylinder", st["specimen/centre"], st["specimen/size"]).all()
    # and the aggregate share on the mastic lattice matches the cut stage's within a few percent
    assert int(m["aggregate_cells"]) / cells == pytest.approx(1 - float(st["specimen/porosity"]), abs=0.04)
    # and the mastic balls overlap no other mastic ball (a touching lattice)
    from scipy.spatial import cKDTree

    pairs = cKDTree(centres).query_pairs(2 * r * (1 - 1e-9))
    assert not pairs


def test_mastic_count_follows_mass_and_density(smoke_run, tmp_path):
    st = _remastic(smoke_run, tmp_path, ["stages.mastic.amount={by: mass, mass: 1.2345 g}"])
    m = st.groups["mastic"]
    unit = 2000.0 * (2 * float(m["ball_radius"])) ** 3
    # Then N = round(M / (rho (2r)^3)): the placed mass is within half a ball of the asked mass
    assert abs(float(m["mass"]) - 1.2345e-3) <= 0.5 * unit
    assert int(m["count"]) == round(1.2345e-3 / unit)
    assert np.isnan(float(m["air_voids_target"]))


def test_too_much_mastic_for_the_voids_is_a_clear_error(smoke_run, tmp_path):
    with pytest.raises(StageError, match="hold only"):
        _remastic(smoke_run, tmp_path, ["stages.mastic.amount={by: mass, mass: 50 g}"])


def test_phase_pair_table_is_complete_and_validated(smoke_run):
    from demcli.stages.asphalt.mastic import phase_problems, phase_table

    st = read_state(smoke_run / "05-mastic.h5")
    table = phase_table(st)
    # Then every pair of phases has its model, with the seed's assignment and strengths
    assert table[("aggregate", "aggregate")][0] == "linear_slip"
    model, prm = table[("aggregate", "mastic")]
    assert model == "contact_bond" and prm["cb_normal_strength"] == 5.0 and prm["cb_shear_strength"] == 5.0
    model, prm = table[("mastic", "mastic")]
    assert model == "parallel_bond" and prm["pb_normal_strength"] == 1e6 and prm["pb_radius_multiplier"] == 1.0
    assert str(np.asarray(st["phases/internal_model"]).reshape(-1)[0]) == "rigid_clump"
    # and a stored table missing a pair, or a strength, is refused with the reason
    bad = st.copy()
    g = bad.groups["phases"]
    keep = [0, 1]
    for k in ("pair_phases", "pair_model", "pair_params"):
        g[k] = np.asarray(g[k])[keep]
    assert any("mastic-mastic" in p for p in phase_problems(bad))
    with pytest.raises(StateError, match="no contact model for the phase pair mastic-mastic"):
        phase_table(bad)
    bad = st.copy()
    names = [str(n) for n in bad["phases/param_names"]]
    bad.groups["phases"]["pair_params"][1, names.index("cb_normal_strength")] = np.nan
    with pytest.raises(StateError, match="cb_normal_strength must be > 0"):
        phase_table(bad)


def _mastic_config_case(tmp_path, edit):
    data = yaml.safe_load(SMOKE.read_text())
    edit(data["stages"][5])
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_missing_pair_or_strength_is_a_config_error(tmp_path):
    from demcli.stages.base import load_case

    def drop_pair(stage):
        stage["contacts"] = stage["contacts"][:2]

    with pytest.raises(ConfigError, match="no contact model for the phase pair mastic-mastic"):
        load_case(_mastic_config_case(tmp_path, drop_pair))

    def drop_strength(stage):
        del stage["contacts"][1]["shear_strength"]

    with pytest.raises(ConfigError, match=r"contacts\[1\]\.shear_strength: required key is missing"):
        load_case(_mastic_config_case(tmp_path, drop_strength))

    def twice(stage):
        stage["contacts"].append(dict(stage["contacts"][0]))

    with pytest.raises(ConfigError, match="already has a model"):
        load_case(_mastic_config_case(tmp_path, twice))


def test_vtu_tells_aggregates_by_id_and_class_from_mastic(smoke_run):
    st = read_state(smoke_run / "05-mastic.h5")
    mesh = meshio.read(smoke_run / "mastic" / "specimen.vtu")
    pd = mesh.point_data
    phase = np.asarray(pd["phase"])
    assert len(phase) == len(st["spheres/radius"])
    assert set(np.unique(phase)) == {0, 1}
    agg = np.asarray(pd["aggregate"])
    assert np.all(agg[phase == 1] == -1) and np.all(agg[phase == 0] >= 0)
    assert np.array_equal(np.asarray(pd["size_class"])[phase == 0], st["aggregates/size_class"][agg[phase == 0]])
    assert np.all(np.asarray(pd["size_class"])[phase == 1] == -1)
    carve = meshio.read(smoke_run / "carve" / "aggregates.vtu")
    assert set(np.unique(carve.point_data["phase"])) == {0}


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_cell_lattice_volume_is_unbiased_when_the_size_is_whole_cells(shape):
    """A specimen whose height (and, for the box, every side) is a whole number of cells a:
    the voxel specimen is exactly that many layers (a lattice of ceil(L/a) + 1 points put a
    layer of centres on each end face and counted both: one layer too many, +1/12 of the
    volume at 12 layers). Tolerance: a box of whole cells is exact (1e-9 relative); a
    cylinder's layers are exact and each layer's disc is the lattice count of a circle of
    radius R / a = 10 ... 25 cells (Gauss circle problem: the error grows slower than the
    perimeter, measured 0.6 % at these sizes), so its volume is held to 1.5 %."""
    import math

    from demcli.stages.asphalt.mastic import cell_centres

    size = np.array([20e-3, 20e-3, 12e-3])
    centre = np.array([0.011, 0.013, 0.007])
    true = float(np.prod(size)) if shape == "box" else math.pi / 4 * size[0] ** 2 * size[2]
    for a in (1e-3, 0.5e-3, 0.4e-3):
        pts = cell_centres(shape, centre, size, a)
        layers = np.unique(np.round((pts[:, 2] - centre[2]) / a, 6))
        assert len(layers) * a == pytest.approx(size[2], rel=1e-9)
        # and no centre on an end face: the outermost layers are half a cell inside
        assert np.abs(pts[:, 2] - centre[2]).max() == pytest.approx(0.5 * size[2] - 0.5 * a, rel=1e-9)
        vol = len(pts) * a ** 3
        assert vol == pytest.approx(true, rel=1e-9 if shape == "box" else 0.015)
    # and a size that is not whole cells: within half a cell per axis (round(L / a) layers)
    pts = cell_centres("box", centre, size, 0.7e-3)
    assert len(np.unique(np.round(pts[:, 2] / 0.7e-3, 6))) == round(12 / 0.7)


def test_mastic_mass_matches_its_target_on_a_whole_cell_specimen(smoke_run, tmp_path):
    # Given: the smoke cylinder (15 x 15 mm) and mastic cells of a = 0.75 mm, 20 across and 20 high
    st = _remastic(smoke_run, tmp_path, ["stages.mastic.ball_radius=0.375 mm"])
    m = st.groups["mastic"]
    a = 2 * float(m["ball_radius"])
    cells = int(m["cells"])
    # Then the voxel specimen is the specimen within the lattice's error (1.5 %, see above)
    assert cells * a ** 3 == pytest.approx(float(st["specimen/volume"]), rel=0.015)
    # and the mastic balls sit in the 20 layers, none on an end face
    z = st.sphere_centres()[st["phases/sphere"] == 1][:, 2] - st["specimen/centre"][2]
    assert np.abs(z).max() <= 0.5 * float(st["specimen/size"][2]) - 0.5 * a + 1e-12
    # and the mastic mass is its target, rho (n_cells (1 - VV) - n_agg) a^3, within half a ball
    rho = float(m["density"])
    target = rho * (cells * (1 - 0.04) - int(m["aggregate_cells"])) * a ** 3
    assert float(m["mass_target"]) == pytest.approx(target, rel=1e-12)
    assert abs(float(m["mass"]) - target) <= 0.5 * rho * a ** 3
