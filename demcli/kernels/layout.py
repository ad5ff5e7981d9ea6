"""Constants shared by the step kernel and the Python plan (importing this loads no numba)."""

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
LOADED = 32        # an actor: the body carries a prescribed external force (its row of the load table)

# positions in the neighbour-state tuple ``nl`` of :func:`demcli.kernels.step.run_steps`
NL_FIELDS = ("start", "pi", "pj", "rstart", "rlist", "ft", "mr", "fc", "tj", "act", "epair",
             "wstart", "wsph", "wwall", "wft", "wmr", "wfc", "xref", "wref")
(NL_START, NL_PI, NL_PJ, NL_RSTART, NL_RLIST, NL_FT, NL_MR, NL_FC, NL_TJ, NL_ACT, NL_EPAIR,
 NL_WSTART, NL_WSPH, NL_WWALL, NL_WFT, NL_WMR, NL_WFC, NL_XREF, NL_WREF) = range(len(NL_FIELDS))
