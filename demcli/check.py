"""``demcli check``: validate a case and print its plan without compiling anything.

For each ``dem`` stage the plan shows the active effects, the passes that will run,
the arrays that will be allocated, and the time step with its fraction of the critical
step, estimated from the smallest particle of the nearest earlier ``generate`` stage.
"""

import math

import numpy as np


def _set_estimate(case, st):
    """(radius, mass, material index, clump) of the smallest particle of one generate set."""
    from demcli.stages.specimen.sizes import radius_range

    r = radius_range(st.radius)[0]
    rho = case.materials[st.material].density
    if case.dimension == 2:
        m = rho * case.thickness * math.pi * r * r
    else:
        m = rho * 4.0 / 3.0 * math.pi * r ** 3
    if st.clump is not None:
        t = np.array(st.clump.spheres, float)
        m *= float((t[:, 3] ** 3).sum())
        r *= float(t[:, 3].min())
    return r, m, list(case.materials).index(st.material), st.clump is not None


def _scene_estimate(case, k):
    """(radius, mass, material index, clumps) of the smallest particle generated before stage k
    (of several sets: the smallest sphere, and whether any set is of clumps)."""
    from demcli.stages.specimen.generate import particle_sets

    for cfg in reversed(case.stages[:k]):
        if cfg.type != "generate":
            continue
        each = [_set_estimate(case, st) for st in particle_sets(cfg)]
        r, m, mat, _ = min(each, key=lambda e: e[0])
        return r, m, mat, any(e[3] for e in each)
    return None


def describe_case(path, overrides=()):
    """Text of the validated case's plan."""
    from demcli.engine.materials import critical_time_step, pair_table
    from demcli.stages import dem
    from demcli.stages.base import STAGE_TYPES, load_case
    from demcli.stages.timing import step_count, time_step

    case = load_case(path, overrides)
    lines = [f"case {path}: valid; {len(case.stages)} stages, dimension {case.dimension}, seed {case.seed}",
             "materials: " + ", ".join(case.materials)]
    for k, cfg in enumerate(case.stages):
        lines.append(f"\n[{k:02d}] {cfg.name} ({cfg.type})")
        st_type = STAGE_TYPES[cfg.type]
        if st_type.describe is not None:
            lines += ["  " + line for line in st_type.describe(cfg, case).splitlines()]
        if cfg.type != "dem":
            continue
        scene = _scene_estimate(case, k)
        kinds = [c.type for c in case.stages[:k] if c.type in ("assemble", "clumpify")]
        poly = bool(kinds) and kinds[-1] == "assemble"
        clumped = bool(kinds) and kinds[-1] == "clumpify"  # polyhedra made clumps of spheres
        plan = dem.plan_summary(case, cfg, {"clumps": bool(scene and scene[3]) or clumped, "polyhedra": poly})
        lines += ["  " + line for line in plan.describe().splitlines()]
        if cfg.walls:
            lines.append(f"  walls: {len(dem.build_walls(cfg, case, path, f'stages[{k}].walls'))}")
        if scene is None:
            lines.append("  time step: decided at run time from the bodies of the input state "
                         f"({cfg.time.dt_factor:g} x critical)" if cfg.time.dt is None else
                         f"  time step: {cfg.time.dt:.4g} s (checked against the critical step at run time)")
            continue
        r, m, mat, _ = scene
        model = dem.contact_model(cfg)
        mats = dem.case_materials(case)
        dtc = critical_time_step(model, pair_table(mats, model), mats, np.array([m]), np.array([r]),
                                 np.array([0]), np.array([mat]))
        dt = time_step(dtc, cfg.time.dt, cfg.time.dt_factor, allow_unstable=True)  # describes; the run checks dt
        steps = step_count(cfg.time, dt)
        lines.append(f"  time step: {dt:.4g} s = {dt / dtc:.3g} x critical {dtc:.4g} s "
                     f"({model.law}); up to {steps} steps")
    return "\n".join(lines)


def warmup():
    """Compile the engine kernels on a tiny scene (fills numba's cache)."""
    import time

    from demcli.engine.materials import ContactModel, Material
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System, Walls

    t0 = time.perf_counter()
    n = 8
    x = np.stack([np.arange(n) * 2.1e-3, np.zeros(n), np.zeros(n)], axis=1)
    m = np.full(n, 1e-5)
    groups = {"bodies": {"x": x, "v": np.zeros((n, 3)), "omega": np.zeros((n, 3)), "q": np.tile([1.0, 0, 0, 0], (n, 1)),
                         "mass": m, "inertia": np.full((n, 3), 4e-12), "flags": np.zeros(n, np.int8),
                         "id": np.arange(n)},
              "spheres": {"body": np.arange(n), "offset": np.zeros((n, 3)), "radius": np.full(n, 1e-3),
                          "material": np.zeros(n, np.int64)}}
    plan = make_plan(["gravity", "friction"])
    s = System(groups, [Material("m", 2500.0)], ContactModel(), plan, Walls(), Dynamics(), dt=1e-7)
    s.advance(2)
    return f"kernels compiled and cached in {time.perf_counter() - t0:.1f} s"
