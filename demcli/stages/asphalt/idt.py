"""``idt``: indirect tension (Brazilian, diametral compression) of a bonded cylindrical specimen
(issue #32; AASHTO T 322 / ASTM D6931 geometry).

The specimen of a ``prepare`` stage (group ``bonded_specimen``: a cylinder of diameter D and
thickness t along z), or the 3D Marshall specimen of the seed-000 chain (a ``cut`` stage's cylinder
filled by the ``mastic`` stage, bonded here by ``bonds: {from_phases: true, create: true}``), is
loaded across a diameter (``orientation: diametral``, the only one it takes), along x, between
two rigid flat heads: plane walls touching its outermost spheres, one fixed, the other moving at
the constant head speed ``speed`` (the standards: 50.8 mm/min; a DEM run affords far faster,
see the quasi-static check). For an elastic disk under a line load P, the stress across the loaded diameter is a uniform
tension sigma = 2 P / (pi t D) (Timoshenko & Goodier, sec. 41), the indirect tensile strength
ITS = 2 P_max / (pi t D) at the peak load. The standards' 12.7 mm curved loading strips spread the
load; flat heads load the outermost spheres, which the elastic centre stress does not notice
(the strip changes it by under 1 % for a strip of D/8) but which can crush the contact zone.

2D (a case with ``dimension: 2``, e.g. the discretized section of seed 001, or any planar bonded
disk): the disks are a plane-stress slice of the case's ``thickness`` t (no stress out of the
plane; masses and bond springs are those of the slice), loaded along x in their plane; D is the
heads' first distance (the disk of spheres as the heads find it), and the Brazilian centre stress
2 P / (pi t D) holds as in the cylinder (the elastic solution of a disk under diametral loads
does not depend on the elastic constants, so plane stress and plane strain give the same stress).
A section cut by a ``polygons`` stage must be a circle. Bonds: those of the input, or ``bonds:
{create: true, ...}`` bonds the touching spheres at the stage start (the 2D chain ends unbonded).

Records ``records/<stage>_idt`` (CSV + PNG): time, deformation (the heads' approach), load P
(the moving head's force, compression positive), nominal stress 2 P / (pi t D), intact and broken
bonds (tension, shear), and the quasi-static measure E_k / W (the bodies' kinetic energy over the
head's work until then, :func:`demcli.stages.asphalt.common.kinetic_to_work`). The stage stops
after the peak, when the load has fallen below ``post_peak`` of the peak with at least 1 % of the
bonds broken (a failed specimen), or at ``max_deformation``. Result group ``idt_result``: peak
load, ITS, deformation at the peak, and E_k / W at the peak. A warning goes to the log when
E_k / W exceeds ``quasi_static`` (0.01) on a row up to the peak, once the work has reached 5 % of
the work at the peak: 1 % of the work in motion rather than in strain and losses means the head's load is within about that of the static one (the 3D smoke case at
10 mm/s: 1.2e-4, and its ITS moves under 0.1 % when the speed is halved); halve the speed to
check. Broken bonds by mode: ``output.force_chains`` writes the bonds with their state as VTU
lines (docs/measure.md).
"""

import math

import numpy as np

from demcli.stages.asphalt.common import lab_case_check, orientation_check
from demcli.stages.dem import config_inputs
from demcli.stages.asphalt.diametral import declare_outputs, loading_fields, run_loading, specimen
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, register_stage
from demcli.state.records import describe_column

describe_column("tensile_stress", "Nominal tensile stress", "Pa", "MPa", 1e-6, table="idt",
                doc="2 P / (pi t D): the elastic tension across the loaded diameter")
declare_outputs("idt", "Indirect tension test result", [
    ("peak_load", "N", "largest load P_max"), ("its", "Pa", "indirect tensile strength 2 P_max / (pi t D)"),
    ("deformation_at_peak", "m", "heads' approach at the peak load"), ("diameter", "m", "specimen diameter D"),
    ("thickness", "m", "specimen thickness t"),
    ("kinetic_to_work", "1", "kinetic energy at the peak / the head's work until then")])


def nominal_stress(load, thickness, diameter):
    """sigma = 2 P / (pi t D) [Pa]: the elastic tension across the loaded diameter of a disk."""
    return 2.0 * load / (math.pi * thickness * diameter)


def _heads(cfg, x, rad, base, thickness):
    """The fixed and the moving head (plane walls normal to x, touching the outermost spheres)."""
    from demcli.config.schema import Node

    lo, hi = float(np.min(x[:, 0] - rad)), float(np.max(x[:, 0] + rad))
    z0, z1 = base[2], base[2] + thickness
    ext = (lo, float(np.min(x[:, 1] - rad)), z0, hi, float(np.max(x[:, 1] + rad)), z1)
    common = {"material": cfg.head_material, "lay_on_particles": None}
    return [Node({"type": "plane", "name": "fixed", "point": (lo, base[1], base[2]), "normal": (1.0, 0.0, 0.0),
                  "motion": None, "extent": (lo, *ext[1:3], lo, *ext[4:]), **common}),
            Node({"type": "plane", "name": "head", "point": (hi, base[1], base[2]), "normal": (-1.0, 0.0, 0.0),
                  "motion": Node({"mode": "velocity", "velocity": (-cfg.speed, 0.0, 0.0)}),
                  "extent": (hi, *ext[1:3], hi, *ext[4:]), **common})], hi - lo


def _case_check(cfg, case, k, scene, report):
    """The test stages' rules (:func:`lab_case_check`), and a 2D section cut by a polygons stage
    must be a circle (a disk is what the Brazilian solution describes)."""
    from demcli.stages.base import earlier_stage

    lab_case_check(cfg, case, k, scene, report)
    orientation_check(cfg, case, k, report, "diametral", "indirect tension")
    section = earlier_stage(case, k, "polygons") if case.dimension == 2 else None
    if section is not None and section.specimen.shape != "circle":
        report("", f"indirect tension is a test of a disk: the section of stage {section.name!r} is not one; give "
                   "it specimen: {shape: circle, radius: ...}", section.specimen.shape)


def run_idt(ctx, cfg, state_in):
    """Diametral compression of the bonded specimen to failure between flat heads (module doc;
    the loading: :func:`demcli.stages.asphalt.diametral.run_loading`)."""
    x = state_in.sphere_centres()  # (a clump's members: the 2D section's aggregates)
    rad = np.asarray(state_in.groups["spheres"]["radius"])
    D, t, base = specimen(ctx, state_in.groups, x)
    walls, gap0 = _heads(cfg, x, rad, base, t)
    D = gap0 if D is None else D

    def result(p, d, ratio):
        its = nominal_stress(p, t, D)
        group = {"peak_load": np.float64(p), "its": np.float64(its), "deformation_at_peak": np.float64(d),
                 "diameter": np.float64(D), "thickness": np.float64(t), "kinetic_to_work": np.float64(ratio)}
        line = (f"indirect tension: peak load {p / 1e3:.4g} kN at {d * 1e3:.4g} mm, ITS = 2 P / (pi t D) = "
                f"{its / 1e6:.4g} MPa (D {D * 1e3:.4g} mm, t {t * 1e3:.4g} mm); kinetic energy / work at the peak "
                f"{float(group['kinetic_to_work']):.3g}")
        return group, line, "lower the speed (halving it should leave the ITS unchanged)"

    return run_loading(ctx, cfg, state_in, walls, gap0, D, "idt",
                       ({"tensile_stress": "Pa"}, lambda p: {"tensile_stress": nominal_stress(p, t, D)}), result)


register_stage(StageType(
    "idt", loading_fields("head speed (the standards: 50.8 mm/min)"), run_idt, needs_input=True,
    requires=("bodies/x", "spheres/radius"),
    provides=ENGINE_OUTPUT + ("idt_result/*",), keeps=ENGINE_KEEPS + ("bonded_specimen",),
    case_check=_case_check, config_requires=config_inputs,
    doc="indirect tension (diametral compression) of a bonded cylinder or 2D disk section: load, ITS = 2 P / (pi t D)"))
