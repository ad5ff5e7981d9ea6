"""The periodic cell of a sphere scene on the Python side: its kernel array, its state group, its measures.

The kernel side (minimum image, affine deformation, Love-Weber stress, servo) is
:mod:`demcli.kernels.periodic`; the equations are in docs/periodic.md. The cell is the box
[0, L_x) x [0, L_y) x [0, L_z) [m]; the state group ``cell`` keeps the kernel array whole, so
a resumed stage continues bit-identically (its lengths, strain rates, last stress and the
lengths its strains are measured from).
"""

import math

import numpy as np

from demcli.kernels import layout as P
from demcli.state.fields import Field, register, register_group

register_group("cell", "The periodic cell of a sphere scene (dem stage key periodic; docs/periodic.md)",
               writer="stage dem")
register(Field("cell/lengths", "f", (3,), "m", "cell edge lengths L_x, L_y, L_z; the cell is [0, L) per axis",
               writer="stage dem", finite=True))
register(Field("cell/state", "f", (P.N_CELL,), "", "the engine's cell array (demcli/kernels/periodic.py, C_*: "
               "lengths, strain rates, modes, targets, gain, max rate, stress, stiffness, lengths at the stage "
               "start)", writer="stage dem", finite=True))


def spheres_box(x, rad):
    """(low corner, lengths) [m] of the box bounding the spheres: as a periodic cell no sphere
    overlaps another's image (each face touches at most the spheres against it)."""
    lo = (x - rad[:, None]).min(axis=0)
    return lo, (x + rad[:, None]).max(axis=0) - lo


def make_cell(lengths, stress=(None, None, None), rate=(0.0, 0.0, 0.0), gain=0.01, max_rate=1.0):
    """The kernel array of a cell of ``lengths`` [m], its strains measured from them: per axis a
    target ``stress`` [Pa] (servo) or, where that is None, a strain ``rate`` [1/s]; a stress axis
    starts at rest (the servo sets its rate after the first step)."""
    cell = np.zeros(P.N_CELL)
    cell[P.C_L:P.C_L + 3] = lengths
    cell[P.C_L0:P.C_L0 + 3] = lengths
    for d in range(3):
        servo = stress[d] is not None
        cell[P.C_MODE + d] = P.STRESS if servo else P.RATE
        cell[P.C_TARGET + d] = stress[d] if servo else rate[d]
        cell[P.C_RATE + d] = 0.0 if servo else rate[d]
    cell[P.C_GAIN] = gain
    cell[P.C_MAX_RATE] = max_rate
    return cell


def new_cell(lengths, cfg):
    """:func:`make_cell` as ``cfg`` (the stage's ``periodic`` section) says."""
    axes = [cfg[a] for a in "xyz"]
    return make_cell(lengths, [a.stress if a.mode == "stress" else None for a in axes],
                     [a.rate if a.mode == "rate" else 0.0 for a in axes], cfg.gain, cfg.max_rate)


def stage_cell(cfg, groups, x, rad, resume):
    """The kernel array of a stage's cell, and the shift [m] to add to the positions (zeros on
    resume and when the input has a cell). A resumed stage takes its checkpoint's array as it
    is; a fresh one takes the lengths of its input's cell, of ``cfg.cell``, or of the spheres'
    bounding box, in that order, and measures its strains from them."""
    stored = groups.get("cell")
    if resume:
        return np.array(stored["state"], np.float64), np.zeros(3)
    if cfg.cell is not None:
        lo = np.asarray(cfg.cell.min, float)
        return new_cell(np.asarray(cfg.cell.max, float) - lo, cfg), -lo
    if stored is not None:
        return new_cell(np.asarray(stored["lengths"], np.float64), cfg), np.zeros(3)
    lo, lengths = spheres_box(x, rad)
    return new_cell(lengths, cfg), -lo


def reach_problem(cell, rad, skin):
    """A message when an edge is too short for the minimum image (L_d <= 2 (2 r_max + skin)), else None."""
    need = 2.0 * (2.0 * float(rad.max()) + skin)
    short = [f"L_{a} = {cell[P.C_L + d]:.4g} m" for d, a in enumerate("xyz") if cell[P.C_L + d] <= need]
    if short:
        return (f"periodic cell too small: {', '.join(short)} <= 2 (2 r_max + skin) = {need:.4g} m "
                "(a sphere would reach two images of another); use a larger cell or more spheres")
    return None


def groups(cell):
    """The state group ``cell``."""
    return {"lengths": cell[P.C_L:P.C_L + 3].copy(), "state": cell.copy()}


_COLUMN_DOCS = (
    ("cell_<a>", "Cell edge <a>", "m", "mm", 1e3, "edge length L_<a> of the periodic cell"),
    ("strain_<a>", "Cell strain <a>", "1", "%", 100.0, "engineering strain L_<a> / L0_<a> - 1 from the stage start, "
                                                         "extension positive"),
    ("rate_<a>", "Strain rate <a>", "1/s", None, 1.0, "strain rate of the cell along <a> (servo or prescribed), "
                                                      "extension positive"),
    ("s_<a><a>", "Stress <a><a>", "Pa", "kPa", 1e-3, "Love-Weber normal stress of the cell, compression positive"),
)
COLUMNS = {}
"""Record columns of a periodic stage (``dem`` table, beside its coordination 2 N_c / N): cell
edges, engineering strains (L - L0) / L0 (extension positive), strain rates, the Love-Weber
stress (compression positive), p = tr(sigma) / 3, q = sqrt(3 J2) (= |sigma_zz - sigma_xx| under
axisymmetric load), volumetric strain V / V0 - 1 and porosity 1 - V_spheres / V."""


def _describe():
    from demcli.state.records import describe_column

    for name, label, unit, display, scale, doc in _COLUMN_DOCS:
        for a in "xyz":
            sub = name.replace("<a>", a)
            COLUMNS[sub] = unit
            describe_column(sub, label.replace("<a>", a), unit, display, scale, table="dem", doc=doc.replace("<a>", a))
    for name, label in (("s_xy", "Stress xy"), ("s_xz", "Stress xz"), ("s_yz", "Stress yz")):
        COLUMNS[name] = "Pa"
        describe_column(name, label, "Pa", "kPa", 1e-3, table="dem", doc="Love-Weber shear stress of the cell "
                                                                        "(symmetric part)")
    for name, label, unit, display, scale, doc in (
            ("p", "Mean stress p", "Pa", "kPa", 1e-3, "p = (s_xx + s_yy + s_zz) / 3 of the periodic cell"),
            ("q", "Deviator stress q", "Pa", "kPa", 1e-3, "q = sqrt(3 J2) of the cell's stress (= |s_zz - s_xx| "
                                                         "when s_xx = s_yy)"),
            ("volumetric_strain", "Volumetric strain", "1", "%", 100.0, "V / V0 - 1 of the periodic cell from the "
                                                                        "stage start (dilation positive)"),
            ("porosity", "Porosity", "1", None, 1.0, "1 - sphere volume / cell volume")):
        COLUMNS[name] = unit
        describe_column(name, label, unit, display, scale, table="dem", doc=doc)


_describe()


def deviator(s):
    """(p, q) [Pa] of the stress (xx yy zz xy xz yz): p = tr / 3, q = sqrt(3 J2)."""
    p = (s[0] + s[1] + s[2]) / 3.0
    j2 = ((s[0] - s[1]) ** 2 + (s[1] - s[2]) ** 2 + (s[2] - s[0]) ** 2) / 6.0 + s[3] ** 2 + s[4] ** 2 + s[5] ** 2
    return p, math.sqrt(3.0 * j2)


def record_row(cell, rad):
    """The COLUMNS of the cell now."""
    lengths = cell[P.C_L:P.C_L + 3]
    l0 = cell[P.C_L0:P.C_L0 + 3]
    s = cell[P.C_STRESS:P.C_STRESS + 6]
    vol = float(np.prod(lengths))
    p, q = deviator(s)
    row = {f"cell_{a}": float(lengths[d]) for d, a in enumerate("xyz")}
    row.update({f"strain_{a}": float(lengths[d] / l0[d] - 1.0) for d, a in enumerate("xyz")})
    row.update({f"rate_{a}": float(cell[P.C_RATE + d]) for d, a in enumerate("xyz")})
    row.update({f"s_{k}": float(v) for k, v in zip(("xx", "yy", "zz", "xy", "xz", "yz"), s)})
    row.update(p=p, q=q, volumetric_strain=vol / float(np.prod(l0)) - 1.0,
               porosity=1.0 - float(np.sum(4.0 / 3.0 * math.pi * rad ** 3)) / vol)
    return row
