"""``carve`` stage: aggregates carved from a ball lattice by random plane pairs (seed 000, steps 2-6).

Reads the ``seeds`` of a ``place_spheres`` stage and the ``gradation`` targets, then:

1. fills the seeds' region with balls on a simple cubic lattice (``lattice.count``
   balls along the longest side, or ``lattice.spacing``); ball radius = spacing / 2;
2. cuts each seed sphere (centre c, diameter D) with three pairs of parallel planes,
   each pair symmetric about c (|n_p . (x - c)| <= d_p / 2), the angles between the
   pairs at least ``planes.angle_min`` (``demcli.geometry.carving.random_plane_normals``);
   the spacings: d_max = D u, u uniform in ``planes.longest``; the ratio rho = d_max /
   d_min uniform in [``flat_elongated.ratio``, ``planes.ratio.max``] for a share
   ``flat_elongated.share`` of the particles (flat/elongated) and in
   [``planes.ratio.min``, ``flat_elongated.ratio``) for the rest; d_mid uniform between;
3. the lattice balls whose centres (``membership: centre``) or whole balls (``whole``)
   lie inside the sphere and all six planes become one rigid clump; balls in no
   polyhedron are deleted; a seed that catches no ball, or sieves as dropped fines, is cut
   again with fresh planes of its drawn kind (up to ``REDRAW_MAX`` times), so that the kept
   aggregates hold the drawn flat/elongated share;
4. sieves every clump (projection method, ``demcli.geometry.carving.lattice_clump_sieve_size``)
   into the gradation's classes (lower < size <= upper; below the smallest class: fines,
   dropped by default since finer material belongs to the mastic), compares the class
   mass shares with the targets and adjusts the counts until every class is within
   ``adjust.tolerance`` (relative, e.g. 2 %: |share / target - 1| <= 0.02):
   ``mode: add`` places new seeds of the lacking classes into the gaps (among the
   existing spheres), carves them and sieves them again, and finishes with removals;
   ``mode: remove`` keeps the least represented class and removes random aggregates
   of the others (the seed paper's adjustment); ``none`` only reports.

Output: bodies (aggregates, in cell order) and spheres (members, grouped by body),
the ``aggregates`` group (class, sieve size, volume, cutting planes in the body frame,
flat/elongated measure), ``seeds`` with each seed's fate, ``gradation`` passed on,
``records/classes`` and ``records/adjust`` (CSV + PNG), and ``<stage>/aggregates.vtu``.
"""

import math
import time

import numpy as np

from demcli.config.schema import Float, Int, Optional, Section, Str
from demcli.errors import StageError
# common registers the seeds and aggregates groups
from demcli.stages.asphalt.common import build_aggregate_bodies, copy_group, write_asphalt_vtu
from demcli.stages.base import StageType, earlier_stage, register_stage
from demcli.state.records import describe_column

for _name, _label, _doc in [("target", "Target share", "mass percent of the aggregate in the class, as asked"),
                           ("first", "First-round share", "mass percent after the first carving, before adjusting"),
                           ("achieved", "Achieved share", "mass percent of the carved aggregates")]:
    describe_column(_name, _label, "%", table="classes", doc=_doc)
describe_column("round", "Adjustment round", integer=True, table="adjust", doc="gradation adjustment round")
describe_column("max_error", "Largest class error", "%", table="adjust",
                doc="largest relative error of a class's mass share")

FIELDS = {
    "lattice": Section({
        "count": Optional(Int(min=1), doc="balls along the region's longest side (the seed: 66 in 120 mm)"),
        "spacing": Optional(Float("m", min=0, min_inclusive=False), doc="ball diameter = lattice spacing"),
    }, doc="the ball lattice: give count or spacing"),
    "membership": Str(choices=["centre", "whole"], default="centre",
                      doc="a ball joins a polyhedron when its centre (or the whole ball) is inside"),
    "mass_model": Str(choices=["cells", "balls"], default="cells",
                      doc="a member stands for its lattice cell (polyhedron volume) or for its ball"),
    "planes": Section({
        "angle_min": Float("rad", min=0, max="90 deg", default="60 deg",
                           doc="least angle between two pairs of planes"),
        "longest": Section({"min": Float(min=0, min_inclusive=False, default=0.85),
                            "max": Float(min=0, min_inclusive=False, default=1.0)}, default={},
                           doc="largest spacing d_max / sphere diameter, uniform in [min, max]"),
        "ratio": Section({"min": Float(min=1, default=1.0), "max": Float(min=1, default=5.0)}, default={},
                         doc="d_max / d_min over all particles"),
    }, default={}, doc="random cutting planes"),
    "flat_elongated": Section({
        "share": Float(min=0, max=1, default=0.1, doc="share of particles drawn flat/elongated"),
        "ratio": Float(min=1, min_inclusive=False, default=3.0,
                       doc="d_max / d_min from which a particle is flat/elongated (3, as ASTM D4791 / JTG E42)"),
    }, default={}, doc="control of the flat and elongated share by the spacing ratios"),
    "fines": Str(choices=["drop", "keep"], default="drop",
                 doc="clumps passing the smallest class sieve: deleted (they are mastic) or kept"),
    "adjust": Section({
        "mode": Str(choices=["add", "remove", "none"], default="add"),
        "tolerance": Float(min=0, min_inclusive=False, default=0.02,
                           doc="largest |class mass share / target - 1| accepted"),
        "max_rounds": Int(min=1, default=12),
    }, default={}, doc="gradation check by virtual sieving, and count adjustment"),
}


def _check(node, report):
    lat = node.lattice
    if (lat.count is None) == (lat.spacing is None):
        report("lattice", "give exactly one of count or spacing", None)
    p = node.planes
    if p.longest.max < p.longest.min:
        report("planes.longest.max", f"must be >= planes.longest.min ({p.longest.min:g})", p.longest.max)
    if p.ratio.max < p.ratio.min:
        report("planes.ratio.max", f"must be >= planes.ratio.min ({p.ratio.min:g})", p.ratio.max)
    fe = node.flat_elongated
    if fe.share > 0 and not fe.ratio < p.ratio.max:
        report("flat_elongated.ratio", f"must be below planes.ratio.max ({p.ratio.max:g}) to draw flat/elongated "
               "particles", fe.ratio)
    if fe.share < 1 and not p.ratio.min < fe.ratio:
        report("flat_elongated.ratio", f"must exceed planes.ratio.min ({p.ratio.min:g}) to draw regular particles",
               fe.ratio)


def _case_check(cfg, case, k, scene, report):
    """The ball lattice over the region of the place_spheres stage before: it must fit, and
    the machine must hold its balls."""
    from demcli.config.memory import check_memory
    from demcli.geometry.carving import make_lattice

    seeds = earlier_stage(case, k, "place_spheres")
    if seeds is None:
        return
    key = "lattice.count" if cfg.lattice.count is not None else "lattice.spacing"
    try:
        lat = make_lattice(seeds.region.min, seeds.region.max, spacing=cfg.lattice.spacing, count=cfg.lattice.count)
    except ValueError as exc:
        report(key, f"no lattice in the region of stage {seeds.name!r}: {exc}")
        return
    check_memory(report, key, lat.size, f"the ball lattice over the region of stage {seeds.name!r}")


REDRAW_MAX = 100  # further cuts of a seed that caught no ball or sieved as fines (see Carver.carve)
FE_Z = 3.29  # the flat/elongated share of the kept aggregates is checked against a 99.9 % binomial band


class Carver:
    """The growing set of seeds, their cutting planes and the lattice labels."""

    def __init__(self, rng, cfg, lattice, seeds, density, lower, upper):
        from demcli.geometry.carving import element_volume

        self.rng, self.cfg, self.lat = rng, cfg, lattice
        self.lower, self.upper = lower, upper
        self.density = density  # per material index
        self.label = -np.ones(lattice.size, np.int64)
        self.centre = np.asarray(seeds["centre"], float)
        self.radius = np.asarray(seeds["radius"], float)
        self.cls = np.asarray(seeds["class"], np.int64)
        self.mat = np.asarray(seeds["material"], np.int64)
        self.round = np.asarray(seeds["round"], np.int64)
        n = len(self.radius)
        self.status = np.zeros(n, np.int8)
        self.normals = np.zeros((n, 3, 3))
        self.spacing = np.zeros((n, 3))
        self.rho = np.zeros(n)
        self.pwidth = np.zeros((n, 3))
        self.size = np.full(n, math.nan)
        self.size_class = np.full(n, -2, np.int64)
        self.count = np.zeros(n, np.int64)
        self.fe = np.zeros(n, bool)  # drawn flat/elongated (kept when a seed is cut again)
        self.v_el = element_volume(lattice.spacing, cfg.mass_model)
        self.sieve_seconds = 0.0
        self.recuts = 0  # cuts after a seed's first (see carve)

    @property
    def mass(self):
        return self.count * self.v_el * self.density[self.mat]

    def add(self, centre, radius, cls, mat, rnd):
        k0 = len(self.radius)
        m = len(radius)
        self.centre = np.r_[self.centre, centre]
        self.radius = np.r_[self.radius, radius]
        self.cls = np.r_[self.cls, cls]
        self.mat = np.r_[self.mat, np.full(m, mat, np.int64)]
        self.round = np.r_[self.round, np.full(m, rnd, np.int64)]
        self.status = np.r_[self.status, np.zeros(m, np.int8)]
        self.normals = np.concatenate([self.normals, np.zeros((m, 3, 3))])
        self.spacing = np.concatenate([self.spacing, np.zeros((m, 3))])
        self.rho = np.r_[self.rho, np.zeros(m)]
        self.pwidth = np.concatenate([self.pwidth, np.zeros((m, 3))])
        self.size = np.r_[self.size, np.full(m, math.nan)]
        self.size_class = np.r_[self.size_class, np.full(m, -2, np.int64)]
        self.count = np.r_[self.count, np.zeros(m, np.int64)]
        self.fe = np.r_[self.fe, np.zeros(m, bool)]
        return np.arange(k0, k0 + m)

    def carve(self, ids):
        """Draw planes for seeds ``ids``, claim their balls, sieve them; returns the clash count.

        A seed whose polyhedron catches no lattice ball, or sieves as fines that are dropped,
        is cut again with fresh planes of the kind it was drawn (flat/elongated or regular),
        up to ``REDRAW_MAX`` times. Thin shapes fail far more often than stocky ones (a
        flat/elongated cut of a small seed is a layer or a row of balls, which passes the
        smallest sieve), so without this the kept aggregates held about half the drawn
        flat/elongated share (docs/asphalt3d.md). Seeds still failing after that are
        dropped as before.
        """
        ids = np.asarray(ids, np.int64)
        clash = 0
        todo, kinds = ids, None
        for attempt in range(REDRAW_MAX + 1):
            if len(todo) == 0:
                break
            if attempt:
                self.recuts += len(todo)
            clash += self._cut(todo, kinds)
            todo = todo[self.status[todo] >= 2]  # 2: no ball, 3: fines dropped (their balls are free again)
            kinds = self.fe[todo]
        return clash

    def _cut(self, ids, kinds=None):
        """One cut of seeds ``ids`` (``kinds``: their flat/elongated flags, None: drawn)."""
        from demcli.geometry.carving import (carve, lattice_clump_sieve_size, members_by_label, shape_planes,
                                             sieve_class)

        cfg = self.cfg
        p, fe = cfg.planes, cfg.flat_elongated
        m = len(ids)
        if m == 0:
            return 0
        normals, sp, drawn, rho, widths = shape_planes(self.rng, 2.0 * self.radius[ids], p.angle_min,
                                                       (p.longest.min, p.longest.max), fe.share, fe.ratio,
                                                       (p.ratio.min, p.ratio.max), fe=kinds)
        self.fe[ids] = drawn
        self.status[ids] = 0
        self.size[ids] = math.nan
        self.size_class[ids] = -2
        self.normals[ids] = normals
        self.spacing[ids] = sp
        self.rho[ids] = rho
        self.pwidth[ids] = widths
        clash = carve(self.lat, self.label, self.centre[ids], self.radius[ids], self.normals[ids], sp, ids,
                      cfg.membership)
        start, members = members_by_label(self.label, len(self.radius))
        self.count = np.diff(start)
        t0 = time.perf_counter()
        pts = None
        for k in ids:
            a, b = start[k], start[k + 1]
            if b == a:
                self.status[k] = 2
                continue
            if pts is None:
                pts = self.lat.centres(members)
            self.size[k] = lattice_clump_sieve_size(pts[a:b], self.lat.radius)
        self.sieve_seconds += time.perf_counter() - t0
        got = ids[self.status[ids] != 2]
        self.size_class[got] = sieve_class(self.size[got], self.lower, self.upper)
        self.status[got] = 1
        fines = got[self.size_class[got] < 0]
        if cfg.fines == "drop" and len(fines):
            self.release(fines, 3)
        return clash

    def release(self, ids, status):
        """Delete the aggregates of seeds ``ids`` (their balls become free)."""
        ids = np.asarray(ids, np.int64)
        mask = np.zeros(len(self.radius), bool)
        mask[ids] = True
        hit = self.label >= 0
        self.label[hit & mask[np.maximum(self.label, 0)]] = -1
        self.status[ids] = status
        self.count[ids] = 0

    def class_masses(self):
        act = (self.status == 1) & (self.size_class >= 0)
        return np.bincount(self.size_class[act], self.mass[act], minlength=len(self.lower))

    def yields(self):
        """Mean mass landing in sieve class c per carved seed of placement class c (kg)."""
        n = len(self.lower)
        tried = np.isin(self.status, (1, 2, 3))
        out = np.zeros(n)
        for c in range(n):
            mine = tried & (self.cls == c)
            if mine.sum():
                hit = mine & (self.status == 1) & (self.size_class == c)
                out[c] = self.mass[hit].sum() / mine.sum()
        return out


def _errors(masses, target):
    total = masses.sum()
    share = masses / total if total > 0 else np.zeros_like(masses)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.where(target > 0, share / target - 1.0, np.where(share > 0, np.inf, 0.0))
    return share, err


ADD_MAX_TRIES = 5000  # failed candidates in a row before an add round places no more spheres


def _add_round(ctx, carver, masses, target, tol, rnd, region):
    """Place and carve new seeds for the classes short of the best-represented one."""
    from demcli.geometry.carving import draw_diameters, place_spheres

    pos = target > 0
    ratio = np.where(pos, masses / np.where(pos, target, 1.0), 0.0)
    ref = ratio[pos].max()
    deficit = np.where(pos, ref * target - masses, 0.0)
    y = carver.yields()
    rng = ctx.rng
    lower, upper = carver.lower, carver.upper
    diam, cls = [], []
    for c in np.flatnonzero(deficit > 0.5 * tol * ref * target):
        if y[c] <= 0:
            vol = math.pi / 6 * ((lower[c] + upper[c]) / 2) ** 3
            y[c] = 0.3 * vol * carver.density[carver.mat].mean()
        n = int(math.ceil(deficit[c] / y[c]))
        diam.append(draw_diameters(rng, lower[c], upper[c], n))
        cls.append(np.full(n, c, np.int64))
    if not diam:
        return 0
    diam = np.concatenate(diam)
    cls = np.concatenate(cls)
    act = carver.status == 1
    out, placed = place_spheres(rng, region[:3], region[3:], 0.5 * diam, obstacles=carver.centre[act],
                                obstacle_radii=carver.radius[act], max_tries=ADD_MAX_TRIES)
    ok = ~np.isnan(out[:, 0])
    if not ok.any():
        return 0
    mat = int(np.bincount(carver.mat[act]).argmax()) if act.any() else int(carver.mat[0])
    ids = carver.add(out[ok], 0.5 * diam[ok], cls[ok], mat, rnd)
    carver.carve(ids)
    return int(ok.sum())


def _remove_round(carver, masses, target, tol):
    """Remove random aggregates of the classes above the least-represented one."""
    pos = target > 0
    ratio = np.where(pos, masses / np.where(pos, target, 1.0), np.inf)
    ref = ratio[pos].min()
    goal = ref * target
    removed = []
    mass = carver.mass
    for c in range(len(target)):
        m_c = masses[c]
        if target[c] == 0:
            cand = np.flatnonzero((carver.status == 1) & (carver.size_class == c))
            removed += list(cand)
            continue
        if m_c <= goal[c] * (1 + 0.5 * tol):
            continue
        cand = np.flatnonzero((carver.status == 1) & (carver.size_class == c))
        for k in carver.rng.permutation(cand):
            if m_c <= goal[c] * (1 + 0.25 * tol):
                break
            if m_c - mass[k] >= goal[c] * (1 - 0.25 * tol):
                removed.append(k)
                m_c -= mass[k]
    if removed:
        carver.release(np.array(removed, np.int64), 4)
    return len(removed)


def run(ctx, cfg, state_in):
    from demcli.geometry.carving import make_lattice, normal_widths, members_by_label
    from demcli.state import RecordTable
    from demcli.state.order import spatial_permutation

    t_start = time.perf_counter()
    seeds = state_in.groups["seeds"]
    g = state_in.groups["gradation"]
    lower = np.asarray(g["class_lower"], float)
    upper = np.asarray(g["class_upper"], float)
    target = np.asarray(g["class_share"], float) / 100.0
    region = np.asarray(seeds["region"], float)
    lat = make_lattice(region[:3], region[3:], spacing=cfg.lattice.spacing, count=cfg.lattice.count)
    if lat.spacing > 0.5 * lower[target > 0].min():
        ctx.log(f"warning: ball diameter {lat.spacing * 1e3:.3g} mm is over half the smallest class "
                f"({lower[target > 0].min() * 1e3:g} mm): small aggregates are a few balls")
    density = np.array([m.density for m in ctx.case.materials.values()])
    carver = Carver(ctx.rng, cfg, lat, seeds, density, lower, upper)
    ctx.log(f"lattice {lat.counts[0]} x {lat.counts[1]} x {lat.counts[2]} = {lat.size} balls of "
            f"{lat.spacing * 1e3:.4g} mm; {len(carver.radius)} seed spheres")
    clash = carver.carve(np.arange(len(carver.radius)))
    if clash and "records/expand" not in state_in.groups:
        raise StageError(f"stage {ctx.name}: {clash} lattice balls fell inside two seed spheres; the seeds overlap "
                         "(they must come from a place_spheres stage)")
    if clash:  # seeds packed by radius expansion overlap by design: a contested ball stays with its first seed
        ctx.log(f"{clash} lattice balls fell inside two overlapping seed polyhedra (radius-expanded seeds) and stay "
                "with the first (seeds in the order drawn)")
    volume_box = float(np.prod(region[3:] - region[:3]))
    tol = cfg.adjust.tolerance
    rounds = RecordTable("adjust", {"round": "1", "max_error": "%", "aggregates": "1", "added": "1",
                                    "removed": "1", "porosity": "1"})
    first_share = None
    added = removed = 0
    converged = False
    for rnd in range(cfg.adjust.max_rounds + 1):
        masses = carver.class_masses()
        share, err = _errors(masses, target)
        if first_share is None:
            first_share = share.copy()
        act = carver.status == 1
        worst = float(np.abs(err).max()) if masses.sum() > 0 else math.inf
        rounds.append(round=rnd, max_error=100 * worst, aggregates=int(act.sum()), added=added, removed=removed,
                      porosity=1 - carver.count[act].sum() * lat.spacing ** 3 / volume_box)
        if worst <= tol:
            converged = True
            break
        if masses.sum() <= 0:
            raise StageError(f"stage {ctx.name}: no aggregate of any class survived carving (lattice balls of "
                             f"{lat.spacing * 1e3:.3g} mm against classes from {lower.min() * 1e3:g} mm); use a "
                             "finer lattice")
        if cfg.adjust.mode == "none" or rnd == cfg.adjust.max_rounds:
            break
        added = removed = 0
        if cfg.adjust.mode == "add" and rnd < cfg.adjust.max_rounds - 2:
            added = _add_round(ctx, carver, masses, target, tol, rnd + 1, region)
            if added == 0:
                removed = _remove_round(carver, masses, target, tol)
        else:
            removed = _remove_round(carver, masses, target, tol)
    masses = carver.class_masses()
    share, err = _errors(masses, target)
    if not converged and cfg.adjust.mode != "none":
        raise StageError(
            f"stage {ctx.name}: class mass shares {np.round(100 * share, 2).tolist()} % against targets "
            f"{np.round(100 * target, 2).tolist()} % after {cfg.adjust.max_rounds} rounds (largest error "
            f"{100 * np.abs(err).max():.3g} %, tolerance {100 * tol:g} %); enlarge the region (more particles per "
            "class), raise adjust.max_rounds or adjust.tolerance")

    # ---- the aggregates: active seeds in cell order ----
    act = np.flatnonzero(carver.status == 1)
    start_all, members = members_by_label(carver.label, len(carver.radius))
    pts_all = lat.centres(members)
    owner = carver.label[members]
    n_seed = len(carver.radius)
    com = np.stack([np.bincount(owner, pts_all[:, d], n_seed) for d in range(3)], axis=1)[act] \
        / np.maximum(carver.count[act], 1)[:, None]
    order = act[spatial_permutation(com)]
    counts = carver.count[order]
    start = np.r_[0, np.cumsum(counts)].astype(np.int64)
    pts = np.concatenate([pts_all[start_all[k]:start_all[k + 1]] for k in order]) if len(order) else \
        np.zeros((0, 3))
    rho_agg = density[carver.mat[order]]
    bodies, spheres, planes, cs = build_aggregate_bodies(
        start, pts, lat.radius, rho_agg, cfg.mass_model, carver.normals[order], carver.spacing[order],
        carver.centre[order], carver.radius[order], carver.mat[order])
    widths = carver.pwidth[order]
    ratio = widths.max(axis=1) / widths.min(axis=1)
    ball_widths = normal_widths(start, pts, carver.normals[order], lat.radius)
    ball_fe = ball_widths.max(axis=1) / ball_widths.min(axis=1) >= cfg.flat_elongated.ratio
    n_agg = len(order)
    aggregates = {
        "body": np.arange(n_agg, dtype=np.int64), "seed": order.astype(np.int64),
        "seed_class": carver.cls[order], "size_class": carver.size_class[order], "sieve_size": carver.size[order],
        "volume": counts * carver.v_el, **planes, "widths": widths, "ball_widths": ball_widths,
        "drawn_ratio": carver.rho[order],
        "flat_elongated": (ratio >= cfg.flat_elongated.ratio).astype(np.int8),
        "ball_radius": np.float64(lat.radius), "lattice_origin": np.asarray(lat.origin, float),
        "lattice_counts": np.asarray(lat.counts, np.int64), "mass_model": np.array(cfg.mass_model, dtype=object),
        "fe_ratio": np.float64(cfg.flat_elongated.ratio)}
    seeds_out = {"centre": carver.centre, "radius": carver.radius, "class": carver.cls, "material": carver.mat,
                 "status": carver.status, "round": carver.round, "region": region}

    state = ctx.new_state()
    state.groups["bodies"] = bodies
    state.groups["spheres"] = spheres
    state.groups["aggregates"] = aggregates
    state.groups["seeds"] = seeds_out
    state.groups["gradation"] = copy_group(state_in, "gradation")
    table = RecordTable("classes", {"lower": "mm", "upper": "mm", "target": "%", "first": "%", "achieved": "%",
                                    "error": "%", "mass": "kg", "count": "1", "flat_elongated": "%",
                                    "flat_elongated_balls": "%"})
    size_class = aggregates["size_class"]
    for c in range(len(lower)):
        mine = size_class == c
        table.append(lower=lower[c] * 1e3, upper=upper[c] * 1e3, target=100 * target[c], first=100 * first_share[c],
                     achieved=100 * share[c], error=100 * err[c] if np.isfinite(err[c]) else 0.0,
                     mass=float(masses[c]), count=int(mine.sum()),
                     flat_elongated=100 * float(aggregates["flat_elongated"][mine].mean()) if mine.any() else 0.0,
                     flat_elongated_balls=100 * float(ball_fe[mine].mean()) if mine.any() else 0.0)
    table.to_state(state)
    rounds.to_state(state)
    ctx.write_records(table, x="upper", ys=["target", "first", "achieved"])
    ctx.write_records(rounds, x="round", ys=["max_error"])
    write_asphalt_vtu(ctx.snapshot_dir / "aggregates.vtu", state)
    porosity = 1 - float(aggregates["volume"].sum()) / volume_box
    fmt = " : ".join
    norm_t = target[::-1] / target[::-1][0] if target[-1] > 0 else target[::-1]
    f0 = first_share[::-1] / target[::-1][0] if target[-1] > 0 else first_share[::-1]
    fa = share[::-1] / target[::-1][0] if target[-1] > 0 else share[::-1]
    st = np.bincount(carver.status, minlength=5)
    ctx.log(f"{n_agg} aggregates of {len(members)} balls ({len(members) / lat.size:.1%} of the lattice); "
            f"porosity {porosity:.4f}; {st[2]} seeds caught no ball, {st[3]} fines dropped (after {carver.recuts} "
            f"new cuts of such seeds, up to {REDRAW_MAX} each), {st[4]} removed, {int((carver.round > 0).sum())} added")
    ctx.log(f"class mass ratios (largest class first) {fmt(f'{v:.3f}' for v in f0)} before adjustment, "
            f"{fmt(f'{v:.3f}' for v in fa)} after, target {fmt(f'{v:.3g}' for v in norm_t)}; largest error "
            f"{100 * np.abs(err).max():.2f} % (tolerance {100 * tol:g} %); flat/elongated "
            f"{100 * aggregates['flat_elongated'].mean():.1f} % of the polyhedra (drawn "
            f"{100 * cfg.flat_elongated.share:g} %), {100 * ball_fe.mean():.1f} % by their balls' extents; "
            f"sieving {carver.sieve_seconds:.1f} s of {time.perf_counter() - t_start:.1f} s")
    p_fe, fe_share = cfg.flat_elongated.share, float(aggregates["flat_elongated"].mean()) if n_agg else 0.0
    band = FE_Z * math.sqrt(p_fe * (1 - p_fe) / max(n_agg, 1))
    if n_agg and abs(fe_share - p_fe) > band:
        ctx.log(f"warning: flat/elongated share of the aggregates {100 * fe_share:.1f} % is outside the binomial "
                f"band {100 * p_fe:g} +- {100 * band:.1f} % of the drawn share: thin cuts of the smallest seeds "
                f"rarely hold balls of {lat.spacing * 1e3:.3g} mm (see docs/asphalt3d.md); a finer lattice helps")
    return state


def describe(cfg, case):
    lat = cfg.lattice
    size = f"{lat.count} balls along the longest side" if lat.count is not None else \
        f"spacing {lat.spacing * 1e3:g} mm"
    return (f"lattice: {size}; planes at >= {math.degrees(cfg.planes.angle_min):g} deg, d_max/D in "
            f"[{cfg.planes.longest.min:g}, {cfg.planes.longest.max:g}]; flat/elongated "
            f"{100 * cfg.flat_elongated.share:g} % (ratio >= {cfg.flat_elongated.ratio:g}); adjust {cfg.adjust.mode} "
            f"to {100 * cfg.adjust.tolerance:g} %")


register_stage(StageType(
    "carve", FIELDS, run, check=_check, describe=describe, case_check=_case_check,
    requires=("seeds/centre", "seeds/radius", "seeds/region", "gradation/class_lower", "gradation/class_share"),
    provides=("bodies/*", "spheres/*", "aggregates/*", "seeds/*", "records/*"), keeps=("gradation",),
    doc="aggregates carved from a ball lattice by three random plane pairs per seed sphere (seed 000)"))
