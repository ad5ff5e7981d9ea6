"""Seed spheres packed by radius expansion with relaxation (seed 000's porosity 15 %, #32 item 1),
where random sequential addition jams."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.errors import StageError
from demcli.state import read_state

SMOKE = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "asphalt_carved_cube.yaml"
POROSITY = 0.30  # beyond random sequential addition (it jams near 0.5 for these sizes), below seed 000's 0.15


def _case(tmp_path, **place):
    """The carved-cube smoke chain up to its seed spheres, with the place stage's keys replaced."""
    case = yaml.safe_load(SMOKE.read_text())
    k = next(i for i, s in enumerate(case["stages"]) if s["type"] == "place_spheres")
    case["stages"] = case["stages"][:k + 1]
    case["stages"][k].update(place)
    path = tmp_path / "seeds.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    return path, case["stages"][k]


@pytest.fixture(scope="module")
def expanded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("expand")
    path, stage = _case(tmp, target={"kind": "porosity", "porosity": POROSITY}, expand={"start": 0.7})
    run_case(path, out=tmp / "run", quiet=True)
    return tmp / "run", stage


def test_random_sequential_addition_jams_below_the_target(tmp_path):
    path, _ = _case(tmp_path, target={"kind": "porosity", "porosity": POROSITY}, max_tries=2000)
    with pytest.raises(StageError, match="jams near 0.5"):
        run_case(path, out=tmp_path / "run", quiet=True)


def test_expansion_reaches_the_target_with_spread_overlaps(expanded):
    out, _ = expanded
    st = read_state(next(out.glob("01-*.h5")))
    x, r = np.asarray(st["seeds/centre"]), np.asarray(st["seeds/radius"])
    lo, hi = np.asarray(st["seeds/region"])[:3], np.asarray(st["seeds/region"])[3:]
    volume = float(np.prod(hi - lo))
    # Then the spheres have their drawn sizes at the target's solid fraction (overlaps counted in each
    # sphere, as PFC counts a porosity), to the draw's last sphere
    assert 1 - 4 / 3 * math.pi * np.sum(r ** 3) / volume == pytest.approx(POROSITY, abs=4.2 * r.max() ** 3 / volume)
    # and every centre lies in the region, no sphere deeper than 40 % of its radius in a face (the faces
    # push as hard as a neighbour does: their overlaps are the packing's, ~33 % at most here)
    assert np.all(x > lo) and np.all(x < hi)
    assert np.all(np.minimum(x - lo, hi - x).min(axis=1) > 0.6 * r)
    # and the overlaps are spread: the mean overlap a few % of the smaller radius (measured 6.5 %), none
    # half of it (28 %), so no sphere's centre lies inside another sphere
    rows = read_record(out / "records" / "seeds_expand.csv")[0]
    assert rows["radius_factor"][-1] == 1.0 and rows["solid_fraction"][-1] == pytest.approx(
        4 / 3 * math.pi * np.sum(r ** 3) / volume, rel=1e-12)
    assert rows["overlap_mean"][-1] < 0.1 and rows["overlap_max"][-1] < 0.5
    # and the relaxation ended in equilibrium (unbalanced force below 1 % of the mean contact force)
    assert rows["unbalanced"][-1] < 0.01


def test_bad_expand_input_is_reported():
    result = CliRunner().invoke(cli, ["check", str(SMOKE), "--set", "stages.seeds.expand={start: 1.5}"])
    assert result.exit_code == 2 and "expand.start" in result.output, result.output
