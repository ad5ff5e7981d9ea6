# YADE Polyhedra on demcli's loaded bed: the same stones, sleeper load, walls, time step, friction and
# local damping, with YADE's volumetric law at the same contact stiffness at the bed's median contact area.
# Export the bed first:  python bench/bench_loaded_bed.py --export /tmp/bed.npz
# Run:                   yade -j1 -n -x bench/yade_loaded_bed.py /tmp/bed.npz [STEPS=200] [REPEAT=3]
# It runs 200 steps for YADE's contacts to take the load, then REPEAT windows of STEPS steps; prints the median
# body-steps/s, the touching pairs and the cost per touching pair-step. LAST line: particle_steps_per_s=<median>.
#
# Differences that remain (YADE 2023.02a's Polyhedra): F_N = k V (ours k_n sqrt(V d): equal stiffness for a flat
# overlap of the median area, yade_young in the export); the tangential stiffness is young * poisson [N/m]
# (poisson = 0.25 k A_median / young: ours K_t = 0.25 k_n sqrt(A)); no normal dashpot (ours: restitution 0.3);
# walls are YADE's axis-aligned infinite planes (ours are such planes too); the sleeper is a polyhedron free
# along z only, pushed by a constant force (ForceEngine).
import math
import statistics
import sys
import time

import numpy as np
from yade import polyhedra_utils  # noqa: F401  (registers the Polyhedra classes)

PATH = sys.argv[1]
STEPS = int(sys.argv[2]) if len(sys.argv) > 2 else 200
REPEAT = int(sys.argv[3]) if len(sys.argv) > 3 else 3
d = np.load(PATH)
vs = d["vertex_start"]
n = len(d["mass"])
young = float(d["yade_young"])
area = float(d["contact_area_median"])
kt = 0.25 * float(d["kn"]) * math.sqrt(area)        # our K_t at the median area [N/m]
mat = PolyhedraMat(density=2600, young=young, poisson=kt / young, frictionAngle=math.atan(float(d["friction"])))
O.materials.append(mat)
bodies = []
for b in range(n):
    verts = [Vector3(*map(float, p)) for p in d["vertices"][vs[b]:vs[b + 1]]]
    body = polyhedra_utils.polyhedra(mat, v=verts)
    m0 = body.state.mass
    body.state.mass = float(d["mass"][b])
    body.state.inertia = body.state.inertia * (float(d["mass"][b]) / m0)
    body.state.vel = Vector3(*map(float, d["v"][b]))
    bodies.append(body)
ids = O.bodies.append(bodies)
actors = [int(k) for k in d["actor_body"]]
for k in actors:
    O.bodies[k].state.blockedDOFs = "xyXYZ"
wall_ids = []
for p, nrm in zip(d["wall_point"], d["wall_normal"]):
    axis = int(np.argmax(np.abs(nrm)))
    assert abs(abs(nrm[axis]) - 1.0) < 1e-12, "YADE walls are axis-aligned"
    wall_ids.append(O.bodies.append(wall(float(p[axis]), axis=axis, sense=int(np.sign(nrm[axis])), material=mat)))
load = d["actor_load"]
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Polyhedra_Aabb(), Bo1_Wall_Aabb()]),
    InteractionLoop([Ig2_Wall_Polyhedra_PolyhedraGeom(), Ig2_Polyhedra_Polyhedra_PolyhedraGeom()],
                    [Ip2_PolyhedraMat_PolyhedraMat_PolyhedraPhys()],
                    [Law2_PolyhedraGeom_PolyhedraPhys_Volumetric()]),
    ForceEngine(ids=actors, force=Vector3(*map(float, load[0]))),
    NewtonIntegrator(damping=float(d["local_damping"]), gravity=Vector3(*map(float, d["gravity"]))),
]
O.dt = float(d["dt"])


def touching():
    return sum(1 for I in O.interactions if I.isReal and I.geom.penetrationVolume > 0
               and I.id1 not in wall_ids and I.id2 not in wall_ids)


O.run(200, True)
rates = []
for _ in range(REPEAT):
    t0 = time.time()
    O.run(STEPS, True)
    rates.append(n * STEPS / (time.time() - t0))
pairs = touching()
med = statistics.median(rates)
print("peer=yade version=%s threads=%d" % (version, O.numThreads))
print("loaded bed %s: %d bodies, young %.4g (k = %.4g N/m^3), median contact area %.3g m^2, demcli's touching pairs %d"
      % (PATH, n, young, young / 2, area, int(d["touching_pairs"])))
print("%.4g body-steps/s (runs %s); %d touching pairs (%.2f per body); %.3g us per touching pair-step"
      % (med, ", ".join("%.4g" % r for r in rates), pairs, 2.0 * pairs / n, n / med / max(pairs, 1) * 1e6))
print("particle_steps_per_s=%.6g" % med)
