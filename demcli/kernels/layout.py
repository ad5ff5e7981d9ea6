"""Constants and argument tuples shared by the engine kernels and the Python side (importing this loads no numba)."""

from collections import namedtuple

# kernel switches of the one body engine: index into the flags tuple (all bool), set by the plan
# from the effect registry (demcli.effects.registry: each effect names its flag)
FLAG_NAMES = ("clumps", "friction", "rolling", "energy", "planar", "gravity", "local", "viscous", "bonds",
              "dashpot", "adaptive")
(F_CLUMPS, F_FRICTION, F_ROLLING, F_ENERGY, F_PLANAR, F_GRAVITY, F_LOCAL, F_VISCOUS, F_BONDS,
 F_DASHPOT, F_ADAPTIVE) = range(len(FLAG_NAMES))
N_FLAGS = len(FLAG_NAMES)

# pass counters: one increment per executed pass per step
COUNTERS = ("kick", "members", "wallmove", "rebuild", "pairs", "gather", "body", "wallctrl", "check",
            "friction", "rolling", "energy", "gravity", "damping", "bonds")
(C_KICK, C_MEMBERS, C_WALLMOVE, C_REBUILD, C_PAIRS, C_GATHER, C_BODY, C_WALLCTRL, C_CHECK,
 C_FRICTION, C_ROLLING, C_ENERGY, C_GRAVITY, C_DAMPING, C_BONDS) = range(len(COUNTERS))
N_COUNTERS = len(COUNTERS)

# guard status codes
OK, BAD_NUMBER, BAD_OVERLAP, BAD_ENERGY = range(4)
STATUS_TEXT = {OK: "ok", BAD_NUMBER: "NaN or Inf in the body state", BAD_OVERLAP: "overlap beyond the limit",
               BAD_ENERGY: "runaway kinetic energy"}

# body flag bits
FIX_TRANSLATION = 1
FIX_ROTATION = 2
FIX_X = 4          # velocity component x held at its value (FIX_X << d for axis d)
FIX_Y = 8
FIX_Z = 16
FIX_XYZ = FIX_X | FIX_Y | FIX_Z
LOADED = 32        # an actor: the body carries a prescribed external force (its row of the load table)

# the tuples the engine's kernels take (numba named tuples of arrays and numbers)
Bodies = namedtuple("Bodies", "x v w q L f tq mass inert flags load")
"""Body state: x, v, w (omega), L (world angular momentum; rigid rotors), f, tq (the loads of the last
step) (n_b, 3); q (n_b, 4) body to world (w, x, y, z); mass (n_b,) kg; inert (n_b, 3) principal
moments kg m^2; flags (n_b,) int8 (FIX_*, LOADED); load (n_b, N_LOAD) actor forces (motion.L_*)."""

Params = namedtuple("Params", "dt law gravity local visc skin max_cells nsmall check_every overlap_limit ke_limit")
"""Numbers of a run: dt [s]; law (contact law code of the sphere laws); gravity (3,) m/s^2; local
(Cundall lambda); visc (alpha [1/s]); skin [m]; max_cells; nsmall (primitives 0..nsmall-1 go
through the cell grid, the rest are actors); check_every; overlap_limit; ke_limit [J]."""

MeshArrays = namedtuple("MeshArrays", "verts tris vstart tstart lo dims cell cstart cbase clist lbase")
"""Triangle meshes of the mesh walls (kind walls.MESH), all walls' concatenated: wall w's vertices
verts[vstart[w]:vstart[w + 1]] (m, relative to the wall's point: the mesh translates with it), its
triangles tris[tstart[w]:tstart[w + 1]] (int64, indices into its own vertices), its cell grid
(:func:`demcli.kernels.mesh.bin_triangles`): origin lo[w] (3,), dims[w] (3,) int64, cell edge cell[w],
cell starts cstart[cbase[w]:cbase[w + 1]] into its list clist[lbase[w]:lbase[w + 1]]. None in
WallArrays when the scene has no mesh wall (:func:`demcli.kernels.mesh.mesh_arrays`): nothing
allocated, and the kernels are compiled without the mesh path (demcli.kernels.switch)."""

WallArrays = namedtuple("WallArrays", "kind point normal radius v material control prm force kn mesh")
"""Walls: kind (int8), point, normal, radius, v, material, control (int8), prm (W_* columns),
force (sum of contact forces on each wall), kn (servo stiffness), mesh (MeshArrays, or None)."""

Contacts = namedtuple("Contacts", "start pi pj rstart rlist ft mr fc tj act epair geo sep sdir sclear pbox "
                                  "wstart wprim wwall wft wmr wfc wtq wen wgeo xref wref")
"""Neighbour and contact state, rebuilt by the engine: pair CSR (start, pi, pj; i < j) and its
reverse (rstart, rlist); per pair tangential spring ft, rolling spring mr, force on i fc, torque on
j tj, touching flag act (uint8), losses epair; polyhedra: geo (depth, F_N, K_t), sep / sdir (the
cached separating face or direction), sclear (its clearance plus both bodies' travel when it
was found: the pair stays apart while the bodies' travel since is smaller), pbox (the bounding box of the last intersection, low xyz, high
xyz: the next evaluation's culling box; zeros when the pair did not touch); per primitive-wall contact wstart, wprim, wwall, wft, wmr,
wfc (force on the primitive, servo stiffness, normal force), wtq (torque on the primitive), wen
(dashpot and slip losses of the step), wgeo; xref (positions at the last
list build), wref (wall displacement since). Arrays of inactive effects have zero rows."""

Members = namedtuple("Members", "mstart mlist xs fs ts")
"""Clumps: mstart (n_b + 1,), mlist (n_s,) the member spheres of each body; xs their positions, fs, ts
their loads (n_s, 3). Zero rows (mstart of length 1) when the bodies are their own primitives."""

# slots of a periodic cell's array (demcli/kernels/periodic.py; docs/periodic.md)
C_L = 0          # (3) edge lengths L_d [m]
C_RATE = 3       # (3) strain rates edot_d [1/s] (extension positive)
C_MODE = 6       # (3) RATE: the rate is prescribed (C_TARGET); STRESS: servo to the stress C_TARGET
C_TARGET = 9     # (3) prescribed rate [1/s] or target stress [Pa] (compression positive)
C_GAIN = 12      # beta: share of the stress error the servo closes per step (affine estimate)
C_MAX_RATE = 13  # edot_max [1/s]
C_STRESS = 14    # (6) xx yy zz xy xz yz [Pa], compression positive, measured at the last step
C_STIFF = 20     # (3) affine stiffness K_d [Pa]
C_L0 = 23        # (3) lengths at the stage start [m] (strains are measured from them)
N_CELL = 26
RATE, STRESS = 0, 1
