"""Marshall stability and flow (``marshall``, issue #32 item 3): the smoke case end to end, the
breaking heads' placement against the specimen, and bad input."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.state import read_state

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "cases" / "smoke" / "marshall_stability.yaml"
HEAD = ROOT / "cases" / "meshes" / "marshall_head.stl"
D, T = 20e-3, 4e-3


@pytest.fixture(scope="module")
def broken(tmp_path_factory):
    out = tmp_path_factory.mktemp("marshall") / "run"
    run_case(SMOKE, out=out, quiet=True)
    return out


def test_the_load_rises_to_a_peak_and_falls(broken):
    rows = read_record(broken / "records" / "break_marshall.csv")[0]
    p, d = np.asarray(rows["load"]), np.asarray(rows["deformation"])
    res = read_state(broken / "01-break.h5")
    k = int(np.argmax(p))
    # Then the curve rises from the first touch to a peak inside the record and falls after it
    assert 0 < k < len(p) - 1 and p[k] > 0 and p[-1] < 0.5 * p[k] and np.all(np.diff(d) > 0)
    # and the stability is the peak load, the flow the deformation there (also in 0.25 mm units)
    assert float(res["marshall_result/stability"]) == p[k] > 0
    assert float(res["marshall_result/flow"]) == d[k] > 0
    assert float(res["marshall_result/flow_value"]) == pytest.approx(d[k] / 0.25e-3, rel=1e-12)
    assert float(res["marshall_result/diameter"]) == D and float(res["marshall_result/thickness"]) == T
    assert float(res["marshall_result/head_scale"]) == pytest.approx(0.5 * D / 50.8, rel=1e-6)
    # and the loading was quasi-static up to the peak
    assert float(res["marshall_result/kinetic_to_work"]) < 1e-2
    assert "kinetic_to_work" in rows and "broken_tension" in rows
    assert (broken / "records" / "break_marshall.png").stat().st_size > 0


def test_halving_the_speed_leaves_the_stability(broken, tmp_path):
    import shutil

    # Given the same prepared specimen broken at 5 mm/s instead of 10 mm/s
    shutil.copy(broken / "00-prepare.h5", tmp_path / "00-prepare.h5")
    run_case(SMOKE, out=tmp_path, overrides=["stages.break.speed=5 mm/s"], quiet=True)
    # Then stability and flow stay within 1 % (measured: 41.51 N and 41.52 N, flow 0.270 mm both)
    res = [read_state(f / "01-break.h5") for f in (broken, tmp_path)]
    for key in ("stability", "flow"):
        assert float(res[1][f"marshall_result/{key}"]) == pytest.approx(float(res[0][f"marshall_result/{key}"]),
                                                                        rel=0.01)


def _ring(d=D):
    """400 spheres of radius d / 40 at random in a disk of radius 0.475 d, 0.05 d .. 0.15 d above z = 0
    (the specimen seen along z)."""
    rng = np.random.default_rng(3)
    n = 400
    r = 0.475 * d * np.sqrt(rng.random(n))
    a = 2 * np.pi * rng.random(n)
    x = np.c_[r * np.cos(a), r * np.sin(a), d * (0.05 + 0.1 * rng.random(n))]
    return x, np.full(n, d / 40)


@pytest.mark.parametrize("d, scale", [(20e-3, 20 / 101.6 * 1e-3), (101.6e-3, 1e-3)])
def test_heads_touch_the_outermost_spheres_concave_side_in(d, scale):
    from demcli.config.schema import Node
    from demcli.geometry.mesh_file import read_mesh
    from demcli.stages.asphalt.marshall import _gap, _profile, place_heads

    # Given a specimen of spheres of diameter d (20 mm: the smoke case's; 101.6 mm: ASTM D6927's), 0.2 d thick
    x, rad = _ring(d)
    cfg = Node({"speed": 0.01, "head_material": "steel"})
    base = np.array([0.0, 0.0, 0.0])
    walls, s, sep0 = place_heads(cfg, x, rad, d, 0.2 * d, base, HEAD, None, "stages[1]")
    # Then the head file (mm) is scaled to the specimen: 0.001 (mm -> m) for the standard's specimen
    assert s == pytest.approx(scale, rel=1e-6)   # (the file's 50.8 mm arc is float32)
    firsts = []
    for w, side in zip(walls, (-1.0, 1.0)):
        verts, tris = read_mesh(w.file, scale=w.scale, translation=w.translation, rotate=np.degrees(w.rotate))
        firsts.append(verts[0])
        axis = np.asarray(w.translation)
        # Then the head is an arc of radius d/2 about an axis along z (parallel to the specimen's axis) ...
        assert np.allclose(np.hypot(verts[:, 0] - axis[0], verts[:, 1] - axis[1]), 0.5 * d, rtol=1e-6)
        assert np.ptp(verts[:, 2]) == pytest.approx(76.2 * s, rel=1e-6)
        # on the specimen's side `side` of it, its triangles' normals facing the axis (concave side in)
        assert np.all(side * (verts[:, 0] - axis[0]) > 0)
        e = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
        mid = verts[tris].mean(axis=1)
        assert np.all(np.einsum("ij,ij->i", e, axis - mid) > 0)
        # and it touches the outermost spheres: the smallest gap to its faces is zero (to 1e-9 d) ...
        assert abs(_gap(_profile(verts, axis[:2]), x[:, :2], rad)) < 1e-9 * d
        # ... and, against the circle of radius R = d/2 the faces are chords of (16 over 80 degrees: they
        # lie up to R (1 - cos 2.5 deg) = 9.5e-4 R inside it), the spheres facing the arc clear it by 0 .. that
        rel = x[:, :2] - axis[:2]
        facing = side * rel[:, 0] > np.cos(np.radians(40)) * np.hypot(rel[:, 0], rel[:, 1])
        clear = 0.5 * d - np.hypot(rel[facing, 0], rel[facing, 1]) - rad[facing]
        assert 0 <= clear.min() <= 0.5 * d * (1 - np.cos(np.radians(2.5))) + 1e-12
    assert sep0 == firsts[1][0] - firsts[0][0]
    assert walls[0].motion is None and walls[1].motion.velocity == (-0.01, 0.0, 0.0)
    assert walls[0].normal == (1.0, 0.0, 0.0) and walls[1].normal == (-1.0, 0.0, 0.0)


def test_bad_speed_is_a_config_error(tmp_path):
    case = yaml.safe_load(SMOKE.read_text())
    case["stages"][1]["speed"] = "0 mm/s"
    path = tmp_path / "still.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    result = CliRunner().invoke(cli, ["check", str(path)])
    # Then the error names the file, the key, the rule and the value (exit code 2)
    assert result.exit_code == 2 and "still.yaml" in result.output and "stages[1].speed: must be > 0" in result.output
    assert "0 mm/s" in result.output and "Traceback" not in result.output


@pytest.mark.parametrize("head, rule", [("nowhere.stl", "file not found"),
                                        (str(ROOT / "cases" / "meshes" / "make_marshall_head.py"), "must be a")])
def test_bad_head_file_is_a_config_error(tmp_path, head, rule):
    case = yaml.safe_load(SMOKE.read_text())
    case["stages"][1]["head_file"] = head
    path = tmp_path / "headless.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2 and "headless.yaml" in result.output and "stages[1].head_file" in result.output
    assert rule in result.output and "Traceback" not in result.output


def test_a_head_that_is_no_arc_is_a_config_error(tmp_path):
    import meshio

    meshio.write(tmp_path / "flat.stl", meshio.Mesh(np.array([[0.0, 0, -1], [1, 0, -1], [0, 1, -1]]),
                                                    [("triangle", np.array([[0, 1, 2]]))]), binary=True)
    from demcli.errors import ConfigError
    from demcli.stages.asphalt.marshall import head_radius

    with pytest.raises(ConfigError, match="must be an arc about the file's y axis"):
        head_radius(tmp_path / "flat.stl", tmp_path / "case.yaml", "stages[1]")


def test_no_bonded_specimen_is_an_input_error(tmp_path):
    from demcli.errors import InputError

    case = yaml.safe_load(SMOKE.read_text())
    case["stages"][0] = {"name": "prepare", "type": "generate", "region": {"shape": "box", "min": [0, 0, 0],
                                                                           "max": ["20 mm", "20 mm", "4 mm"]},
                         "count": 20, "radius": "1 mm", "material": "sand"}
    case["stages"][1]["bonds"] = {"create": True, "models": case.pop("bond_models", [
        {"model": "contact_bond", "materials": ["sand", "sand"], "kn": "3e5 N/m", "ks": "1.5e5 N/m"}])}
    case["stages"][1]["head_file"] = str(HEAD)
    path = tmp_path / "loose.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2 and "bonded_specimen" in result.output
    from demcli.stages.asphalt.diametral import specimen

    class Ctx:
        name = "break"

        class case:
            dimension = 3
    with pytest.raises(InputError, match="bonded_specimen"):
        specimen(Ctx, {}, np.zeros((3, 3)))


def test_a_specimen_longer_than_the_heads_is_an_input_error():
    from demcli.config.schema import Node
    from demcli.errors import InputError
    from demcli.stages.asphalt.marshall import place_heads

    # Given a 20 mm disk 16 mm thick: the heads scaled to it are 76.2 / 101.6 x 20 = 15 mm long
    x, rad = _ring(D)
    with pytest.raises(InputError, match="longer than the scaled breaking heads"):
        place_heads(Node({"speed": 0.01, "head_material": "steel"}), x, rad, D, 16e-3, np.zeros(3), HEAD, None,
                    "stages[1]")
