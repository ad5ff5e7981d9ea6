"""The one compiled time loop for every body shape: velocity Verlet (kick-drift-kick).

One call advances a chunk of steps without returning to Python. Each step:

1. first half kick, rotation and drift of every body (:func:`demcli.kernels.motion.kick_drift`),
   with the displacement check that triggers a neighbour-list rebuild when a primitive has
   moved more than skin/2 (skipped when the last step's gather already did it, below);
2. the shape's ``place``: clump members follow their body, polyhedra get their world vertices
   and face planes;
3. walls move (prescribed velocity, servo or force control from the last step);
4. rebuild of the pair and wall lists when needed (:func:`rebuild_lists`), history carried over;
5. the shape's ``pair_pass``: one force per pair into its own row, the row owner summing its side;
6. the gather (:func:`gather`): each primitive sums its row, the j sides through the reverse
   list and its wall contacts (computed by the shape's ``wall_pass``), in a fixed order (bit-identical
   for any thread count); a primitive that is its own body then finishes the step
   (:func:`demcli.kernels.motion.finish_body`: body loads, actor force, second half kick) and,
   for spin rotors without adaptive damping, fuses the next step's first kick and drift; clump
   members are summed per body (:func:`member_loads`);
7. adaptive damping (when on): alpha from the step's absorbed and kinetic energy;
8. wall force sums and wall control; every ``check_every`` steps: NaN/Inf, overlap and
   kinetic-energy guards.

The shape plug-ins (:mod:`demcli.kernels.shapes`) provide what differs between spheres,
clumps and polyhedra; numba compiles this loop once per geometry type with the shape's
passes inlined. Effects are switched by the ``flags`` tuple (layout.F_*) built by the plan
from the effect registry; their arrays have zero rows when off.
"""

import numpy as np
from numba import prange, types
from numba.extending import overload

from demcli.jit import njit
from demcli.kernels import motion as M
from demcli.kernels.bonds import unbonded_pairs
from demcli.kernels.layout import (BAD_ENERGY, BAD_NUMBER, BAD_OVERLAP, C_BODY, C_BONDS, C_CHECK, C_DAMPING,
                                   C_ENERGY, C_FRICTION, C_GATHER, C_GRAVITY, C_KICK, C_MEMBERS, C_PAIRS,
                                   C_REBUILD, C_ROLLING, C_WALLCTRL, C_WALLMOVE, Contacts, F_ADAPTIVE, F_BONDS,
                                   F_CLUMPS, F_ENERGY, F_FRICTION, F_GRAVITY, F_LOCAL, F_PLANAR, F_ROLLING,
                                   F_VISCOUS, OK)
from demcli.kernels.neighbors import add_actor_pairs, build_pairs, build_reverse, build_wall_pairs, carry_history
from demcli.kernels.periodic import cell_of, control, deform, wrap
from demcli.kernels.shapes import pair_pass, place, primitives, spin_rotors, volumetric, wall_pass, worst_overlap
from demcli.kernels.switch import choose, on


@njit(internal=True)
def mark_history(act, ft, mr, friction, rolling):
    """Flag carried pairs with history as active, so the pair pass clears it if they opened."""
    for c in range(act.shape[0]):
        if friction and (ft[c, 0] != 0.0 or ft[c, 1] != 0.0 or ft[c, 2] != 0.0):
            act[c] = 1
        if rolling and (mr[c, 0] != 0.0 or mr[c, 1] != 0.0 or mr[c, 2] != 0.0):
            act[c] = 1


@njit(internal=True)
def rebuild_lists(g, bd, nl, par, flags, wa, bonds, bprm, vol, pair_torque):
    """New pair and wall lists on the shape's primitives (actors nsmall.. paired by
    :func:`add_actor_pairs`, bonded pairs left out), history carried over, fresh per-pair arrays
    (zero rows for inactive effects). ``vol``: the shape keeps depth and separation caches."""
    friction = flags[F_FRICTION]
    rolling = flags[F_ROLLING]
    xs, rad, prim_body = primitives(g, bd)
    ns = xs.shape[0]
    nsmall = par.nsmall
    skin = par.skin
    cell = cell_of(g)  # None without a periodic cell (kernels/periodic.py)
    wrap(cell, xs)  # periodic spheres are their bodies: xs is bd.x
    if nsmall < ns:  # actors: the particles alone through the cell grid (contiguous copies)
        nstart, npi, npj = build_pairs(xs[:nsmall].copy(), rad[:nsmall].copy(), prim_body[:nsmall].copy(), skin,
                                       par.max_cells, cell)
        nstart, npi, npj = add_actor_pairs(nstart, npj, xs, rad, prim_body, nsmall, skin)
    else:
        nstart, npi, npj = build_pairs(xs, rad, prim_body, skin, par.max_cells, cell)
    if bonds is not None:  # None (no bond code compiled) for polyhedra and mixed scenes
        if flags[F_BONDS]:
            nstart, npi, npj = unbonded_pairs(bonds, bprm, nstart, npi, npj)
    npair = npi.shape[0]
    nft = np.zeros((npair if friction else 0, 3))
    nmr = np.zeros((npair if rolling else 0, 3))
    carry_history(ns, nstart, npj, nl.start, nl.pj, nl.ft, nft)
    carry_history(ns, nstart, npj, nl.start, nl.pj, nl.mr, nmr)
    npbox = np.zeros((npair if vol else 0, nl.pbox.shape[1]))  # the box (6) and a linearized geometry's
    carry_history(ns, nstart, npj, nl.start, nl.pj, nl.pbox, npbox)
    rstart, rlist = build_reverse(ns, npj)
    act = np.zeros(npair, np.uint8)
    if not vol:
        mark_history(act, nft, nmr, friction, rolling)
    wstart, wprim, wwall, wft, wmr, wfc, wtq, wen, wgeo = (nl.wstart, nl.wprim, nl.wwall, nl.wft, nl.wmr, nl.wfc,
                                                           nl.wtq, nl.wen, nl.wgeo)
    if wa.v.shape[0] > 0:
        nws, nwp, nww = build_wall_pairs(xs, rad, skin, wa.kind, wa.point, wa.normal, wa.radius, wa.mesh)
        nq = nww.shape[0]
        nwft = np.zeros((nq if friction else 0, 3))
        nwmr = np.zeros((nq if rolling else 0, 3))
        carry_history(ns, nws, nww, wstart, wwall, wft, nwft)
        carry_history(ns, nws, nww, wstart, wwall, wmr, nwmr)
        wstart, wprim, wwall, wft, wmr = nws, nwp, nww, nwft, nwmr
        wfc = np.zeros((nq, 5))
        wtq = np.zeros((nq, 3))
        wen = np.zeros((nq if flags[F_ENERGY] else 0, 2))
        wgeo = np.zeros((nq if vol else 0, 3))
        nl.wref[:, :] = 0.0
    return Contacts(nstart, npi, npj, rstart, rlist, nft, nmr, np.empty((npair, 3)),  # fc: read where act only
                    np.zeros((npair if pair_torque else 0, 3)), act,
                    np.zeros((npair if flags[F_ENERGY] else 0, 2)), np.zeros((npair if vol else 0, 3)),
                    np.zeros(npair if vol else 0, np.int32), np.zeros((npair if vol else 0, 3)),
                    np.zeros(npair if vol else 0), npbox,
                    wstart, wprim, wwall, wft, wmr, wfc, wtq, wen, wgeo, xs.copy(), nl.wref)


@njit(parallel=True, internal=True)
def gather(bd, L, fs, ts, own, nl, par, flags, sw, gs, dt, frow, trow, erow, esph, ebody, eabs, kevec, alpha,
           tload, fxref, lim2, rebuild):
    """Per primitive: its own row sums, the j sides of its pairs, its wall contacts; clump
    members keep their loads in fs / ts (Members.fs / .ts) for :func:`member_loads`; a primitive
    that is its own body (fs None) finishes the step (motion.finish_body) and, for spin rotors
    (``fxref``: the list's reference positions; None for rigid rotors) with ``fuse_next``, takes
    the next step's first half kick and drift (the same arithmetic as kick_drift).

    L (None for spin rotors, motion.rotors), fs (None without members), own (None when members
    make up the bodies: the body finish is compiled out) and fxref switch at compile time (numba
    prunes ``is None`` branches on argument types): a scene compiles only its own path.
    gs: (pair_torque, torque, fuse_next); dt: the contact step (0 when priming).
    """
    pair_torque, torque, fuse_next = gs
    h = 0.5 * dt
    cc = M.damping_factors(alpha, h)
    rstart = nl.rstart
    rlist = nl.rlist
    act = nl.act
    fc = nl.fc
    tj = nl.tj
    epair = nl.epair
    wstart = nl.wstart
    wfc = nl.wfc
    wtq = nl.wtq
    wen = nl.wen
    rotate_body = sw[2]
    static = sw[3]
    # arrays taken out of the tuples before the parallel loop (see kernels/shapes/__init__.py)
    x, v, w, q, _, f, tq, mass, inert, bflags, load = bd
    gravity, damping = par.gravity, (par.local, par.visc)
    for i in prange(frow.shape[0]):
        energy = on(static, F_ENERGY)  # constants when static is the literal 0
        planar = on(static, F_PLANAR)
        fx = frow[i, 0]
        fy = frow[i, 1]
        fz = frow[i, 2]
        tx = 0.0
        ty = 0.0
        tz = 0.0
        e0 = 0.0
        e1 = 0.0
        if torque:
            tx = trow[i, 0]
            ty = trow[i, 1]
            tz = trow[i, 2]
        if energy:
            e0 = erow[i, 0]
            e1 = erow[i, 1]
        for a in range(rstart[i], rstart[i + 1]):
            c = rlist[a]
            if act[c]:
                fx -= fc[c, 0]
                fy -= fc[c, 1]
                fz -= fc[c, 2]
                if pair_torque:
                    tx += tj[c, 0]
                    ty += tj[c, 1]
                    tz += tj[c, 2]
                if energy:
                    e0 += epair[c, 0]
                    e1 += epair[c, 1]
        for k in range(wstart[i], wstart[i + 1]):
            fx += wfc[k, 0]
            fy += wfc[k, 1]
            fz += wfc[k, 2]
            tx += wtq[k, 0]
            ty += wtq[k, 1]
            tz += wtq[k, 2]
            if energy:  # a wall contact's loss is wholly the primitive's (pairs split theirs in half)
                e0 += 2.0 * wen[k, 0]
                e1 += 2.0 * wen[k, 1]
        if energy:
            esph[i, 0] += 0.5 * e0
            esph[i, 1] += 0.5 * e1
        if fs is not None:
            fs[i, 0] = fx
            fs[i, 1] = fy
            fs[i, 2] = fz
            ts[i, 0] = tx
            ts[i, 1] = ty
            ts[i, 2] = tz
            if own is None:
                continue
        fx, fy, fz, tx, ty, tz, im, iv = M.finish_body(i, fx, fy, fz, tx, ty, tz, v, w, L, q, inert, mass, bflags, f,
                                                       tq, load, gravity, damping, sw, dt, h, cc, alpha, tload,
                                                       not fuse_next, ebody, eabs, kevec)
        if fxref is not None:
            if fuse_next:  # the next step's first half kick and drift
                M.kick(i, bflags[i], v, w, None, inert, mass[i], im, iv, fx, fy, fz, tx, ty, tz, h, 1.0, 1.0,
                       rotate_body, planar, False)
                M.drift(x, v, i, dt, fxref, lim2, rebuild)


def member_rows(mb):
    """(fs, ts): the clump members' load rows; (None, None) without clumps (mb None), decided at
    compile time (:mod:`demcli.kernels.switch`; plain Python: with NUMBA_DISABLE_JIT=1)."""
    return (None, None) if mb is None else (mb.fs, mb.ts)


@overload(member_rows)
def _member_rows(mb):
    if isinstance(mb, types.NoneType):
        return lambda mb: (None, None)
    return lambda mb: (mb.fs, mb.ts)


def finish_members(bd, mb, par, sw, dt, alpha, tload, ebody, eabs, kevec):
    """:func:`member_loads` for clumps; without clumps (mb None) nothing, decided at compile time
    (plain Python: with NUMBA_DISABLE_JIT=1)."""
    if mb is not None:
        member_loads(bd, mb, par, sw, dt, alpha, tload, ebody, eabs, kevec)


@overload(finish_members)
def _finish_members(bd, mb, par, sw, dt, alpha, tload, ebody, eabs, kevec):
    if isinstance(mb, types.NoneType):
        return lambda bd, mb, par, sw, dt, alpha, tload, ebody, eabs, kevec: None
    return lambda bd, mb, par, sw, dt, alpha, tload, ebody, eabs, kevec: member_loads(bd, mb, par, sw, dt, alpha,
                                                                                      tload, ebody, eabs, kevec)


@njit(parallel=True, internal=True)
def member_loads(bd, mb, par, sw, dt, alpha, tload, ebody, eabs, kevec):
    """Clumps: each body sums its members' forces and torques (about its centre of mass, in
    member order), then finishes the step (motion.finish_body)."""
    h = 0.5 * dt
    cc = M.damping_factors(alpha, h)
    x, v, w, q, L, f, tq, mass, inert, bflags, load = bd
    gravity, damping = par.gravity, (par.local, par.visc)
    mstart = mb.mstart
    mlist = mb.mlist
    xs = mb.xs
    fs = mb.fs
    ts = mb.ts
    for b in prange(x.shape[0]):
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for a in range(mstart[b], mstart[b + 1]):
            s = mlist[a]
            rx = xs[s, 0] - x[b, 0]
            ry = xs[s, 1] - x[b, 1]
            rz = xs[s, 2] - x[b, 2]
            fx += fs[s, 0]
            fy += fs[s, 1]
            fz += fs[s, 2]
            tx += ts[s, 0] + ry * fs[s, 2] - rz * fs[s, 1]
            ty += ts[s, 1] + rz * fs[s, 0] - rx * fs[s, 2]
            tz += ts[s, 2] + rx * fs[s, 1] - ry * fs[s, 0]
        M.finish_body(b, fx, fy, fz, tx, ty, tz, v, w, L, q, inert, mass, bflags, f, tq, load, gravity, damping, sw,
                      dt, h, cc, alpha, tload, True, ebody, eabs, kevec)


@njit(internal=True)
def check(g, bd, L, nl, wa, par, info):
    """Guards: NaN/Inf in the body state, the shape's worst overlap ratio, runaway kinetic energy.
    L: the rotor switch (motion.rotors); info: (body or primitive i, j or -1 for a wall, worst
    ratio, kinetic energy)."""
    ok, ke = M.check_bodies(bd, L, info)
    if not ok:
        return BAD_NUMBER
    worst, wi, wj = worst_overlap(g, nl, wa)
    info[2] = worst
    info[3] = ke
    if worst > par.overlap_limit:
        info[0] = wi
        info[1] = wj
        return BAD_OVERLAP
    if ke > par.ke_limit:
        return BAD_ENERGY
    return OK


@njit(inline="always")
def _count_effects(counters, flags, adaptive):
    """One increment per executed effect pass (the proof that an inactive effect ran nothing)."""
    if flags[F_FRICTION]:
        counters[C_FRICTION] += 1
    if flags[F_ROLLING]:
        counters[C_ROLLING] += 1
    if flags[F_ENERGY]:
        counters[C_ENERGY] += 1
    if flags[F_GRAVITY]:
        counters[C_GRAVITY] += 1
    if flags[F_LOCAL] or flags[F_VISCOUS] or adaptive:
        counters[C_DAMPING] += 1


@njit
def run_steps(nsteps, time, flags, prm, par, bd, g, mb, wa, nl, bonds, bprm, adamp, esph, ebody, eacc,
              counters, info, force_rebuild, step0, prime, static=0):
    """Advance ``nsteps`` steps; returns (status, steps_done, time, nl).

    Args:
        flags: (N_FLAGS,) bool tuple of active effects (layout.F_*).
        prm: material-pair table of the shape's contact law.
        par: Params; bd: Bodies (updated in place); g: the shape's geometry tuple;
        mb: Members (clumps: mstart, mlist, xs, fs, ts) or None (no clumps: member_loads compiles
            to nothing); wa: WallArrays;
        nl: Contacts, rebuilt here when needed.
        bonds: bond state (bstart, bj, brstart, brlist, model, state, hist, bfc, btj, bed), see
            :mod:`demcli.kernels.bonds`; None for polyhedra and mixed scenes (no bond code compiled);
            bprm: (n_models, N_BPARAMS) bond-model table.
        adamp: (N_ADAMP,) adaptive damping state (motion.A_*), updated in place.
        esph: (n_prim, 2) cumulative contact damping and friction losses [J];
        ebody: (n_b,) cumulative body damping losses [J]; eacc: (1,) wall work [J].
        counters: (N_COUNTERS,) int64 pass counters, incremented per executed pass.
        info: (4,) float64 diagnosis of a failed guard (indices, worst overlap, kinetic energy).
        force_rebuild: build the lists before the first step (fresh or resumed system).
        step0: global step count at entry; guards run at global multiples of check_every,
            and after global step 1.
        prime: before the first step, evaluate the loads at the current state with a step of
            zero length (no motion, no history or energy increments), so the first half kick
            uses F(x_0) (a fresh stage; a resumed one keeps its stored loads).
        static: ``switch.static_mask(flags)``, the rarely-on switches of
            :data:`demcli.kernels.switch.STATIC` as one int; omitted when none is on, so that
            numba compiles the scene with them as constants (at most two variants per scene
            type: this one and the run-time one).
    """
    dt = par.dt
    clumps = flags[F_CLUMPS]
    friction = flags[F_FRICTION]
    rolling = flags[F_ROLLING]
    energy = on(static, F_ENERGY)
    bonded = flags[F_BONDS]
    adaptive = on(static, F_ADAPTIVE)
    planar = on(static, F_PLANAR)
    vol = volumetric(g)
    cell = cell_of(g)
    Lr = M.rotors(spin_rotors(g, mb, nl.xref), bd.L)  # None for spin rotors: the rotor switch
    rigid = Lr is not None
    rotate_body = friction or rolling or bonded or rigid
    pair_torque = friction or rolling or vol
    torque = pair_torque or bonded
    body_prims = not clumps
    sw = (flags[F_GRAVITY], flags[F_LOCAL], rotate_body, static)
    nb = bd.x.shape[0]
    nw = wa.v.shape[0]
    lim2 = (0.5 * par.skin) ** 2
    rebuild = np.zeros(1, np.int64)
    rebuild[0] = 1 if force_rebuild else 0
    broke = np.zeros(1, np.int64)
    xs0, _, _ = primitives(g, bd)
    ns = xs0.shape[0]
    fs, ts = member_rows(mb)
    frow = np.zeros((ns, 3))
    trow = np.zeros((ns if torque else 0, 3))
    erow = np.zeros((ns if energy else 0, 2))
    eabs = np.zeros(nb if adaptive else 0)
    kevec = np.zeros(nb if adaptive else 0)
    status = OK
    n = 0
    drifted = False  # the next step's kick and drift were fused into the last gather
    while n < nsteps or prime:
        h = 0.0 if prime else dt
        alpha = adamp[M.A_ALPHA] if adaptive else 0.0
        if prime:
            rebuild[0] = 1
            if adaptive:
                eabs[:] = 0.0
        elif drifted:
            drifted = False
        else:
            M.kick_drift(bd.x, bd.v, bd.w, bd.q, Lr, bd.f, bd.tq, bd.mass, bd.inert, bd.flags, dt, alpha,
                         rotate_body, static, choose(mb, nl.xref, None), lim2, rebuild, eabs)
            counters[C_KICK] += 1
        if not prime:
            deform(cell, bd.x, nl.xref, dt, lim2, rebuild)  # periodic cell: affine remap; else nothing
        place(g, bd, flags, nl.xref, lim2, rebuild)
        if clumps:
            counters[C_MEMBERS] += 1
        if nw > 0 and not prime:
            M.move_walls(wa.point, nl.wref, wa.v, dt, lim2, rebuild)
            M.move_radii(wa.control, wa.prm, wa.radius, nl.wref, dt, lim2, rebuild)
            counters[C_WALLMOVE] += 1
        if rebuild[0]:
            rebuild[0] = 0
            nl = rebuild_lists(g, bd, nl, par, flags, wa, bonds, bprm, vol, pair_torque)
            counters[C_REBUILD] += 1
        fuse_next = body_prims and not rigid and not adaptive and not prime and n + 1 < nsteps
        pair_pass(g, bd, nl, prm, par.law, flags, h, frow, trow, erow, bonds, bprm, broke)
        control(cell, g, nl, bd, prm, par.law, h)  # periodic cell: stress and servo; else nothing
        counters[C_PAIRS] += 1
        if bonded:
            if broke[0]:
                broke[0] = 0
                rebuild[0] = 1
            counters[C_BONDS] += 1
        _count_effects(counters, flags, adaptive)
        if nw > 0:
            wall_pass(g, bd, nl, wa, prm, par.law, flags, h)
        gather(bd, Lr, fs, ts, choose(mb, bd.mass, None), nl, par, flags, sw, (pair_torque, torque, fuse_next), h,
               frow, trow, erow, esph, ebody, eabs, kevec, alpha, time + h, spin_rotors(g, mb, nl.xref), lim2, rebuild)
        counters[C_GATHER] += 1
        if fuse_next:
            drifted = True
            counters[C_KICK] += 1
        finish_members(bd, mb, par, sw, h, alpha, time + h, ebody, eabs, kevec)
        if clumps or vol:
            counters[C_BODY] += 1
        if prime:
            prime = False
            if adaptive:
                ke = 0.0
                for b in range(nb):
                    ke += kevec[b]
                adamp[M.A_KE] = ke
            continue
        if adaptive:
            M.adapt(adamp, eabs, kevec, energy, ebody)
        n += 1
        time += dt
        if nw > 0:
            M.wall_control(time, dt, nl.wstart[ns], nl.wwall, nl.wfc, wa.normal, wa.v, wa.control, wa.prm, wa.force,
                           wa.kn, eacc, energy)
            counters[C_WALLCTRL] += 1
        gstep = step0 + n
        if par.check_every > 0 and (gstep % par.check_every == 0 or gstep == 1):
            status = check(g, bd, Lr, nl, wa, par, info)
            counters[C_CHECK] += 1
            if status != OK:
                break
    return status, n, time, nl
