"""The ``periodic`` key of a dem stage: a periodic cell under stress or strain control (docs/periodic.md).

Schema and rules of the section, the cell a stage starts with (:func:`attach`), and the record
columns (:func:`hooks`). A periodic cell is for spheres-only 3D scenes without walls, bonds or
gravity; the measures that look at positions without the minimum image (regions, fields, force
chains, the packing and contact records) are refused with it.
"""

from demcli.config.schema import Float, Optional, Section, Tagged, Vector
from demcli.engine import periodic_cell  # registers the cell's state group and record columns
from demcli.errors import InputError
from demcli.stages.base import has_field

AXIS = Tagged("mode", {
    "rate": Section({"rate": Float("1/s", default=0.0, doc="strain rate edot = dL/dt / L, extension positive "
                                                           "(compression: negative)")}),
    "stress": Section({"stress": Float("Pa", min=0, doc="target normal stress sigma_dd, compression positive")}),
}, default={"mode": "rate"}, doc="how the cell's edge along this axis moves: a prescribed strain rate, or the servo "
                                 "to a normal stress")


def _check_cell(node, report):
    for d, a in enumerate("xyz"):
        if node.max[d] <= node.min[d]:
            report("max", f"must exceed min along {a}", list(node.max))
            return


PERIODIC = Optional(Section({
    "cell": Optional(Section({"min": Vector(3, "m"), "max": Vector(3, "m")}, check=_check_cell),
                     doc="the cell box; the positions are moved by -min (default: the input's cell, else the box "
                         "bounding the spheres)"),
    "x": AXIS, "y": AXIS, "z": AXIS,
    "gain": Float(min=0, max=1, min_inclusive=False, default=0.01,
                  doc="servo beta: the share of a stress error the servo would close in one step if the packing "
                      "answered affinely; stable for beta < 2, quasi-static for dt / beta >> the cell's wave "
                      "transit time (docs/periodic.md)"),
    "max_rate": Float("1/s", min=0, min_inclusive=False, default=1.0, doc="bound on a servo axis's strain rate"),
}), doc="a periodic orthorhombic cell (spheres only, 3D, no walls, bonds or gravity; docs/periodic.md)")

REFUSED = (("walls", "a periodic cell has no walls"), ("bonds", "bonds are not yet periodic"),
           ("physics.gravity", "a periodic cell has no floor: gravity would accelerate it for ever"),
           ("measure", "the measures are not yet periodic"), ("output.fields", "coarse graining is not yet periodic"),
           ("output.force_chains", "force chains are not yet periodic"),
           ("output.packing", "the packing record is not yet periodic (the cell's records have porosity and "
                              "coordination)"),
           ("output.contacts", "the contact record is not yet periodic"))


def _present(node, key):
    value = node
    for part in key.split("."):
        value = value.get(part) if hasattr(value, "get") else None
        if value is None:
            return None
    if value is False or (hasattr(value, "__len__") and len(value) == 0):
        return None  # off, or an empty list or section
    return value


def check(node, report):
    """The keys a periodic cell cannot run with, each refused with its reason."""
    if node.get("periodic") is None:
        return
    for key, why in REFUSED:
        value = _present(node, key)
        if value is not None:
            report(key, f"is refused with periodic: {why}", value if not hasattr(value, "keys") else None)


def check_scene(node, case, scene, report):
    """A periodic cell is for 3D scenes of single spheres: polyhedra are refused here (``scene``:
    the fields the earlier stages' outputs hold), clumps at the stage start (:func:`attach`)."""
    if node.get("periodic") is None:
        return
    if case.dimension != 3:
        report("periodic", "is for 3D cases", None)
    if has_field(scene, "polyhedra/shape"):  # clumps show in the state only: refused at the stage start
        report("periodic", "is for spheres-only scenes (not clumps or polyhedra yet)", None)


def attach(ctx, cfg, system, groups, resume):
    """Give ``system`` the stage's cell (:func:`demcli.engine.periodic_cell.stage_cell`), its
    positions moved into it; an input error when the scene is not single spheres or the cell is
    too small for the minimum image."""
    import numpy as np

    from demcli.kernels import layout as K

    if system.flags[K.F_CLUMPS] or system.plugin.name != "spheres":
        raise InputError(f"stage {ctx.name}: periodic: is for spheres-only scenes (not clumps or polyhedra yet)")
    cell, shift = periodic_cell.stage_cell(cfg.periodic, groups, system.x, system.rad, resume)
    if np.any(shift != 0.0):
        system.x += shift
    problem = periodic_cell.reach_problem(cell, system.rad, system.skin)
    if problem:
        raise InputError(f"stage {ctx.name}: periodic: {problem}")
    system.cell = cell
    lengths = ", ".join(f"{v * 1e3:.4g}" for v in cell[K.C_L:K.C_L + 3])
    ctx.log(f"periodic cell {lengths} mm")


def hooks():
    """The record columns of a periodic stage (:data:`demcli.engine.periodic_cell.COLUMNS`), its
    stop when the cell has become too small for the minimum image, and its figures
    (``records/<stage>_dem_stress.png``, ``..._strain.png``: against the z strain)."""
    from demcli.stages.loop import Hooks

    def row(system):
        return periodic_cell.record_row(system.cell, system.rad)

    def stop(system, row):  # the minimum image holds while every edge exceeds 2 (2 r_max + skin)
        return periodic_cell.reach_problem(system.cell, system.rad, system.skin)

    def finish(ctx, system, state, table):  # the cell's stresses and volume against the axial (z) strain
        ctx.write_records(table, x="strain_z", ys=["p", "q", "s_xx", "s_yy", "s_zz"], suffix="stress")
        ctx.write_records(table, x="strain_z", ys=["volumetric_strain", "strain_x", "strain_y"], suffix="strain")

    return Hooks(columns=dict(periodic_cell.COLUMNS), row=row, stop=stop, finish=finish)
