"""The peers' "clump" scene (../shared/peers/common/clump_setup.py) as a demcli System.

The clumps, their members and initial velocities come from ``clump_setup.make_case(NC)``
itself (seeded RandomState 777): NC rigid clumps of 5-10 overlapping member spheres,
r = 1 mm, rho = 2650 kg/m^3, on a cubic lattice in a closed box of 6 planar walls (lattice
footprint x twice its height), gravity -9.81 m/s^2 along z, dt = 1e-6 s. The contact law is
the one YADE's ``peers/yade/clump.py`` sets up with ``ViscElMat``: linear spring-dashpot
kn = 1e5 N/m, kt = kn/4, a constant (absolute) normal dashpot cn (drop_setup's CN: e = 0.5
for two single spheres), no tangential damping, Coulomb mu = 0.5; the same values for
member-member and member-wall contacts. Contact constants come from ``drop_setup``.

Mass properties of the overlapping members (``mass=``):

* ``"union"`` (default, demcli's convention): :func:`demcli.engine.clumps.union_mass_properties`
  integrates the union of the members on a voxel grid, so overlaps count once: the clump is
  the solid it looks like. On this scene that is ~56 % of the members' summed mass.
* ``"yade"``: YADE's convention for ``O.bodies.appendClumped(...)`` with its default
  ``discretization=0``: mass = sum of the member masses and inertia = sum of the members'
  inertias about the clump centre (parallel axes), overlaps counted several times, centre of
  mass = mean of the member centres. Clumps are ~1.8x heavier than with ``"union"``.

Both conventions give the same geometry and contact work; the masses change how fast the
pile settles (the dashpot is absolute, so the effective restitution depends on the mass) and
the kinetic energy. The bench uses ``"union"``; ``"yade"`` is for checking that the two codes
do comparable work.

The peers' folder is ../shared/peers (or ``$DEMCLI_PEERS``).
"""

import math
import os
import sys

import numpy as np

from demcli.engine.clumps import union_mass_properties
from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.system import Dynamics, System, Walls

HERE = os.path.dirname(os.path.abspath(__file__))
PEERS_DIR = os.environ.get("DEMCLI_PEERS") or os.path.normpath(os.path.join(HERE, "..", "..", "shared", "peers"))
MASS_CONVENTIONS = ("union", "yade")


def peers_common(peers_dir=None):
    """Import (clump_setup, drop_setup) from the peers' common/ folder."""
    common = os.path.join(peers_dir or PEERS_DIR, "common")
    if not os.path.isfile(os.path.join(common, "clump_setup.py")):
        raise FileNotFoundError(f"no clump_setup.py in {common} (set $DEMCLI_PEERS to the peers/ folder)")
    if common not in sys.path:
        sys.path.insert(0, common)
    import clump_setup
    import drop_setup

    return clump_setup, drop_setup


def _quat_from_matrix(rot):
    """Scalar-first unit quaternion of a rotation matrix (demcli's q layout)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(rot).as_quat()
    return np.array([w, x, y, z])


def yade_mass_properties(centres, r, density):
    """YADE's appendClumped(discretization=0): summed member masses and inertias.

    Returns (mass, centre of mass, principal moments, axes) like union_mass_properties."""
    c = np.asarray(centres, float)
    m1 = density * 4.0 / 3.0 * math.pi * r ** 3
    com = c.mean(axis=0)
    d = c - com
    tensor = len(c) * 0.4 * m1 * r * r * np.eye(3)
    tensor += m1 * (np.einsum("ij,ij", d, d) * np.eye(3) - d.T @ d)
    moments, axes = np.linalg.eigh(tensor)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    return m1 * len(c), com, moments, axes


def make_system(nc=500, skin=0.3, mass="union", resolution=32, peers_dir=None):
    """System of the clump scene; returns (system, info) with info = dict(L, H, n_members).

    ``resolution``: voxels along a clump for ``mass="union"`` (32: ~0.1 % from the converged
    mass here, ~3 s for 500 clumps; part of the set-up, not of the timed loop).
    """
    if mass not in MASS_CONVENTIONS:
        raise ValueError(f"mass must be one of {MASS_CONVENTIONS}, not {mass!r}")
    cs, ds = peers_common(peers_dir)
    p, clumps = cs.make_case(nc)
    r, rho = p["r"], p["rho"]
    nb = len(clumps)
    x = np.empty((nb, 3))
    v = np.empty((nb, 3))
    q = np.empty((nb, 4))
    bmass = np.empty(nb)
    inert = np.empty((nb, 3))
    sbody, soff = [], []
    for b, (members, vel) in enumerate(clumps):
        if mass == "union":
            m, com, mom, axes = union_mass_properties(members, np.full(len(members), r), rho, resolution)
        else:
            m, com, mom, axes = yade_mass_properties(members, r, rho)
        x[b], v[b], q[b] = com, vel, _quat_from_matrix(axes)
        bmass[b], inert[b] = m, mom
        soff.append((members - com) @ axes)   # member centres in the principal frame
        sbody.append(np.full(len(members), b, np.int64))
    sbody = np.concatenate(sbody)
    soff = np.concatenate(soff)
    ns = len(sbody)
    groups = {
        "bodies": {"x": x, "v": v, "omega": np.zeros((nb, 3)), "q": q, "mass": bmass, "inertia": inert,
                   "flags": np.zeros(nb, np.int8), "id": np.arange(nb, dtype=np.int64)},
        "spheres": {"body": sbody, "offset": soff, "radius": np.full(ns, r), "material": np.zeros(ns, np.int64)}}
    lx = ly = p["L"]
    lz = p["H"]
    walls = Walls.box_faces((lx, ly, lz))
    model = ContactModel(law="linear", kn=ds.KN, kt=ds.KT, cn=ds.CN)
    mats = [Material("clump", rho, friction=ds.MU)]
    plan = make_plan(["gravity", "friction"], clumps=True, walls=True)
    system = System(groups, mats, model, plan, walls, Dynamics(gravity=(0, 0, -ds.G), skin=skin), dt=ds.DT)
    return system, dict(L=lx, H=lz, n_members=ns)
