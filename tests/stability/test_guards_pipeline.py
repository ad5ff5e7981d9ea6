"""Each runtime guard of the ``dem`` stage (NaN/Inf, excessive overlap, runaway kinetic energy),
proven through the pipeline for a sphere scene and a polyhedral scene.

The failure is injected into the running stage: ``System.advance`` is
wrapped so that, at the first call that starts at step 300 (right after the record at step
300, where the stage keeps its last good state), it poisons the scene before stepping on. The
guards run every step (``safety.check_every: 1``), so the stage must stop at step 301 with a
diagnosis naming the guard, the bodies and the time step, and keep the state of step 300 in
``NN-stage.lastgood.h5``. tests/test_pipeline.py covers defects present in the stage's input
state and the CLI's exit code.
"""

import math
import textwrap

import numpy as np
import pytest

from demcli import run_case
from demcli.errors import StageError
from demcli.state import new_state, read_state, write_state

POISON_STEP = 300  # records every 100 steps of 2000: the last good state before the failure


def _sphere_case(smoke_case, extra=()):
    """The beads smoke case, settle stage: 2000 steps, 20 records, guards every step."""
    over = ["stages.settle.time.steps=2000", "stages.settle.output.records=20", "stages.settle.output.snapshots=0",
            "stages.settle.safety.check_every=1", *extra]
    return smoke_case, over, "settle", "01-settle"


def _polyhedra_case(tmp_path, extra=()):
    """Four 20 mm cubes (three on the floor, one falling onto them) in an open box: a hand-written
    polyhedral input state ``00-place.h5`` and a case whose ``settle`` dem stage runs on it."""
    from demcli.engine.poly_shape import polyhedra_groups
    from demcli.geometry import convex_hull
    from scipy.spatial.transform import Rotation

    tmp_path.mkdir(parents=True, exist_ok=True)
    case = tmp_path / "cubes.yaml"
    case.write_text(textwrap.dedent("""\
        name: cubes
        seed: 1
        materials:
          rock: {density: 2600 kg/m^3, young: 1e8 Pa, poisson: 0.3, friction: 0.5, restitution: 0.3}
        stages:
          - name: place          # stands in for the stage that made 00-place.h5 (never run here)
            type: generate
            region: {shape: box, min: [0, 0, 0], max: [0.1 m, 0.1 m, 0.1 m]}
            count: 1
            radius: {min: 1 mm, max: 1 mm}
            material: rock
          - name: settle
            type: dem
            physics: {gravity: [0, 0, -9.81], friction: true, local_damping: 0.4}
            walls:
              - {type: box, min: [0, 0, 0], max: [0.1 m, 0.1 m, 0.2 m], material: rock, open: [z1]}
            time: {steps: 2000, dt_factor: 0.1}
            output: {records: 20, snapshots: 0}
            safety: {check_every: 1}
        """))
    a = 0.02
    cube = convex_hull(np.array([[i, j, k] for i in (-a / 2, a / 2) for j in (-a / 2, a / 2) for k in (-a / 2, a / 2)]))
    x = np.array([[0.03, 0.03, 0.011], [0.07, 0.03, 0.011], [0.03, 0.07, 0.011], [0.05, 0.05, 0.035]])
    q = [np.roll(Rotation.from_rotvec([0, 0, 0.1 * k]).as_quat(), 1) for k in range(4)]
    st = new_state("place", "generate", seed=1)
    st.groups.update(polyhedra_groups([cube] * 4, 2600.0, x=x, q=q))
    st.groups["materials"] = {"name": np.array(["rock"], dtype=object),
                              **{k: np.array([v]) for k, v in dict(density=2600.0, young=1e8, poisson=0.3, friction=0.5,
                                                                    rolling_friction=0.0, restitution=0.3).items()}}
    write_state(tmp_path / "00-place.h5", st)
    return case, list(extra), "settle", "01-settle"


def _run(tmp_path, smoke_case, kind, extra=()):
    case, over, stage, stem = (_sphere_case(smoke_case, extra) if kind == "spheres"
                               else _polyhedra_case(tmp_path, extra))
    if kind == "spheres":
        run_case(case, out=tmp_path, quiet=True, only="pour")
    run_case(case, out=tmp_path, quiet=True, only=stage, overrides=over)
    return tmp_path / f"{stem}.h5", tmp_path / f"{stem}.lastgood.h5"


def _poison_nan(s):
    s.v[2, 0] = math.nan
    return "NaN or Inf in the body state of body 2"


def _poison_overlap(s):
    if hasattr(s, "shape"):  # polyhedra: cube 1 pushed a fifth of its edge into cube 0
        s.x[1] = s.x[0] + [0.004, 0.0, 0.0]
        return "body 0 and body 1 overlap to a depth of"
    s.x[1] = s.x[0] + [0.3 * s.rad[0], 0.0, 0.0]
    return "spheres 0 and 1 overlap"


def _poison_energy(s):
    top = int(np.argmax(s.x[:, 2]))
    s.v[top] = [0.0, 0.0, math.sqrt(2.0 * 10.0 * s.ke_limit / s.mass[top])]  # 10 x the limit, upwards
    return "runaway kinetic energy: kinetic energy"


POISONS = {"nan": _poison_nan, "overlap": _poison_overlap, "energy": _poison_energy}
LIMIT_TEXT = {"nan": "", "overlap": "(limit 50 %)", "energy": "exceeds 1000 x the reference energy"}


def _inject(monkeypatch, kind, poison):
    """Wrap the engine's advance: poison the scene once, at the first call starting at POISON_STEP."""
    if kind == "spheres":
        from demcli.engine.system import System as cls
    else:
        from demcli.engine.system import System as cls
    real = cls.advance
    seen = {}

    def advance(self, n):
        if "text" not in seen and self.step >= POISON_STEP:
            assert self.step == POISON_STEP  # chunks end on record steps
            seen["text"] = poison(self)
            seen["time"] = self.time
        return real(self, n)

    monkeypatch.setattr(cls, "advance", advance)
    return seen


@pytest.mark.parametrize("guard", ["nan", "overlap", "energy"])
@pytest.mark.parametrize("kind", ["spheres", "polyhedra"])
def test_guard_stops_the_stage_with_a_diagnosis_and_keeps_the_last_good_state(tmp_path, smoke_case, monkeypatch,
                                                                              kind, guard):
    # Given: a running dem stage (spheres: the beads smoke case, 150 spheres; polyhedra: 4 cubes)
    # whose scene is poisoned at step 300 (a NaN velocity; one body pushed into another; one body
    # sent upwards with 10 x the kinetic-energy limit)
    seen = _inject(monkeypatch, kind, POISONS[guard])
    # When: the stage runs
    with pytest.raises(StageError) as err:
        _run(tmp_path, smoke_case, kind)
    text = str(err.value)
    # Then: it stops at the first guard check after the poison, step 301, with a diagnosis that names
    # the guard, the bodies involved (NaN, overlap) or the energies (runaway), and the time step
    # against the critical one, and says where the last good state is
    assert seen["text"] in text, text
    assert LIMIT_TEXT[guard] in text
    assert f"stopped at step {POISON_STEP + 1} " in text
    assert "of the critical" in text and "last good state kept in" in text
    lastgood = tmp_path / "01-settle.lastgood.h5"
    assert str(lastgood) in text and err.value.state_file == lastgood
    assert not (tmp_path / "01-settle.h5").exists()
    # and the last good state is a valid state file (read_state validates it against the schema) of
    # the scene at step 300, before the failure, with finite positions and velocities and every body
    good = read_state(lastgood)
    assert good.meta["step"] == POISON_STEP and good.meta["time"] == pytest.approx(seen["time"], rel=1e-12)
    assert good.meta["stage"] == "settle"
    assert np.isfinite(good["bodies/x"]).all() and np.isfinite(good["bodies/v"]).all()
    assert len(good["bodies/x"]) == (150 if kind == "spheres" else 4)
    if kind == "polyhedra":
        assert "polyhedra/shape" in good and np.isfinite(good["bodies/q"]).all()


@pytest.mark.parametrize("kind", ["spheres", "polyhedra"])
def test_last_good_state_equals_an_undisturbed_run_to_that_step(tmp_path, smoke_case, monkeypatch, kind):
    # Given: a stage stopped by the NaN guard at step 301 (poisoned at step 300), and the same stage
    # run undisturbed for 300 steps
    _inject(monkeypatch, kind, _poison_nan)
    with pytest.raises(StageError):
        _run(tmp_path / "failed", smoke_case, kind)
    monkeypatch.undo()
    end, _ = _run(tmp_path / "ref", smoke_case, kind, extra=["stages.settle.time.steps=300"])
    # Then: the last good state is that state, bit for bit (positions, velocities, spins, attitudes)
    good = read_state(tmp_path / "failed" / "01-settle.lastgood.h5")
    ref = read_state(end)
    for key in ("bodies/x", "bodies/v", "bodies/omega", "bodies/q"):
        np.testing.assert_array_equal(good[key], ref[key], err_msg=key)


def test_unstable_time_step_stops_polyhedra_with_a_diagnosis(tmp_path):
    # Given: the polyhedral scene with a time step of 5e-3 s, 70 x the critical one (7.1e-5 s;
    # explicitly allowed)
    case, _, _, _ = _polyhedra_case(tmp_path)
    over = ["stages.settle.time.dt=5e-3", "stages.settle.safety.allow_unstable_dt=true"]
    # When: it runs
    with pytest.raises(StageError) as err:
        run_case(case, out=tmp_path, quiet=True, only="settle", overrides=over)
    text = str(err.value)
    # Then: a guard stops it (whichever trips first; measured: the runaway-energy guard at step 4) and
    # the diagnosis says the step is far above the critical one (measured "70.5 of the critical"); the
    # last good state is the start (step 0), valid and finite
    assert "stopped at step" in text and "of the critical" in text
    ratio = float(text.split("time step ")[1].split(" is ")[1].split(" of the critical")[0])
    assert ratio > 10
    good = read_state(tmp_path / "01-settle.lastgood.h5")
    assert good.meta["step"] == 0 and np.isfinite(good["bodies/x"]).all()


def test_runaway_energy_diagnosis_names_the_reference_energy(tmp_path, monkeypatch):
    # Given: the polyhedral stage with one body sent upwards at 10 x the kinetic-energy limit
    _inject(monkeypatch, "polyhedra", _poison_energy)
    with pytest.raises(StageError) as err:
        _run(tmp_path, None, "polyhedra")
    text = str(err.value)
    import re

    ke, ref = map(float, re.search(r"kinetic energy ([0-9.e+-]+) J exceeds 1000 x the reference energy "
                                   r"\(([0-9.e+-]+) J\)", text).groups())
    # Then: "kinetic energy KE J exceeds 1000 x the reference energy (E_ref J)" with
    # KE = 10 x the limit = 1e4 E_ref (before the fix the bracket held the limit, 1000 E_ref)
    assert ke == pytest.approx(1e4 * ref, rel=1e-3)


def test_sphere_driven_deep_into_a_wall_trips_the_overlap_guard(scene):
    # Given: a soft 1 mm sphere (E = 1e7 Pa) hitting a plane at 50 m/s, overlap limit 0.5 of the radius,
    # guards every step, dt = 0.2 x the Rayleigh step (plane walls are half-spaces: it cannot tunnel)
    from demcli.kernels import layout as K

    r = 1e-3
    mats = [scene.Material("m", 2600.0, young=1e7, poisson=0.3, friction=0.0, restitution=1.0)]
    s = scene.spheres([[0, 0, 1.01 * r]], [[0, 0, -50.0]], r, mats, scene.ContactModel(law="hertz_mindlin"),
                      walls=scene.planes([0, 0, 0], [0, 0, 1]), dt_factor=0.2, check_every=1, overlap_limit=0.5)
    # When: it runs through the impact
    status, _ = s.advance(2000)
    # Then: the overlap guard stops it, naming the sphere and a wall (before the fix the guard looked
    # at sphere pairs only and the centre went 0.88 r below the plane, 188 % of the radius, unnoticed)
    assert status == K.BAD_OVERLAP
    assert s.info[0] == 0 and s.info[1] == -1 and s.info[2] > 0.5
