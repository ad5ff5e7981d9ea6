"""The per-contact record (output.contacts): an impact's force and overlap against time from a
case file, checked against Hertz theory (Johnson 1985, sec. 11.4)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from demcli import run_case
from demcli.compare import read_record
from demcli.errors import InputError
from demcli.stages.contact_record import check_scene
from demcli.state import read_state

CASE = """\
name: record
materials:
  al: {density: 2700 kg/m^3, young: 70 GPa, poisson: 0.33, restitution: 1.0, friction: 0.0}
stages:
  - name: balls
    type: particles
    particles:
      - {x: [0, 0, 0.1000001], v: [0, 0, -0.2], radius: 0.1 m, material: al}
      - {x: [1, 0, 1], v: [0.2, 0, 0], radius: 0.1 m, material: al}
      - {x: [1.2000002, 0, 1], v: [-0.2, 0, 0], radius: 0.1 m, material: al}
  - name: impact
    type: dem
    walls: [{type: plane, point: [0, 0, 0], normal: [0, 0, 1], material: al, rigid: true}]
    time: {duration: 1.5 ms, dt: 5e-7 s}
    output: {records: 3000, snapshots: 0, contacts: {}}
"""


def test_contact_record_follows_hertz_for_a_wall_and_a_pair(tmp_path):
    # Given: Chung & Ooi's test 2 (an Al sphere, R = 0.1 m, hits a rigid plane at 0.2 m/s, e = 1)
    # and the same spheres head-on at 0.2 m/s each (test 1 in its setting), one record per step
    path = tmp_path / "case.yaml"
    path.write_text(CASE)
    # When: the case runs
    run_case(path, out=tmp_path / "run", quiet=True, threads=1)
    rec, _ = read_record(tmp_path / "run" / "records" / "impact_contacts.csv")
    m = 2700 * 4 / 3 * math.pi * 0.1 ** 3
    for j, mstar, rstar, estar, v in ((-1, m, 0.1, 70e9 / (1 - 0.33 ** 2), 0.2),
                                      (2, m / 2, 0.05, 70e9 / (2 * (1 - 0.33 ** 2)), 0.4)):
        rows = rec["j"] == j
        # Hertz: delta_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5), F_max = 4/3 E* sqrt(R*) delta_max^(3/2),
        # duration 2.94328 delta_max / v
        dmax = (15 * mstar * v ** 2 / (16 * estar * math.sqrt(rstar))) ** 0.4
        fmax = 4 / 3 * estar * math.sqrt(rstar) * dmax ** 1.5
        # Then: every row obeys the Hertz law F = 4/3 E* sqrt(R*) delta^(3/2) (1e-9: no damping),
        assert np.allclose(rec["fn"][rows], 4 / 3 * estar * math.sqrt(rstar) * rec["overlap"][rows] ** 1.5,
                           rtol=1e-9)
        # the peaks within 0.1 % of Johnson's (the 1 us sampling of a ~1 ms contact) and the duration
        # within 0.2 % (two 0.5 us steps)
        assert rec["overlap"][rows].max() == pytest.approx(dmax, rel=1e-3)
        assert rec["fn"][rows].max() == pytest.approx(fmax, rel=1e-3)
        t = rec["time"][rows]
        assert t[-1] - t[0] == pytest.approx(2.94328 * dmax / v, rel=2e-3)
        # no tangential force (mu = 0), the normal along the line of centres, the point between them
        assert np.all(rec["ft"][rows] == 0.0)
    wall = rec["j"] == -1
    assert np.allclose(rec["nz"][wall], 1.0) and np.all(rec["i"][wall] == 0)
    assert np.allclose(rec["cz"][wall], 0.0, atol=1e-12)  # on the wall's surface
    pair = rec["j"] == 2
    assert np.all(rec["i"][pair] == 1) and np.allclose(rec["nx"][pair], -1.0)
    assert np.allclose(rec["cx"][pair], 1.1000001, atol=1e-9)  # the middle of the overlap (symmetric impact)
    last = read_state(tmp_path / "run" / "01-impact.h5")
    assert "records/contacts" in last.groups


def test_mixed_and_large_unnamed_scenes_are_refused():
    spec = SimpleNamespace(bodies=())
    with pytest.raises(InputError, match="sphere, clump and polyhedron scenes"):
        check_scene(SimpleNamespace(plugin=SimpleNamespace(name="mixed"), rad=np.zeros(3)), spec)
    with pytest.raises(InputError, match="5000 polyhedra"):
        check_scene(SimpleNamespace(plugin=SimpleNamespace(name="polyhedra"), rad=np.zeros(5000)), spec)
    with pytest.raises(InputError, match="name the bodies"):
        check_scene(SimpleNamespace(plugin=SimpleNamespace(name="spheres"), rad=np.zeros(5000)), spec)
    check_scene(SimpleNamespace(plugin=SimpleNamespace(name="spheres"), rad=np.zeros(5000)),
                SimpleNamespace(bodies=(3,)))
