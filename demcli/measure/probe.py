"""The measurement regions' record tables (``measure:`` of a dem stage): one row per region at
every record row (table ``measure_<name>``, ``records/<stage>_measure_<name>.csv``).

Columns (docs/measure.md; stresses compression positive):

* time [s], step; bodies: the bodies whose centre lies in the region; volume [m^3] of the region;
* solid_fraction: solid volume / region volume. Sphere and cylinder regions: the **centre-count
  estimate**, the whole volume of every body whose centre is inside (it errs by the bodies the
  boundary cuts: of the order of d / L for bodies of size d in a region of size L); box and
  ``all`` regions: the exact part of each body inside the box (spheres and polyhedra exactly,
  clumps to within about 2 %: :meth:`demcli.stages.packing_record.PackingProbe.solid_volume`);
* sigma_xx ... sigma_yz [Pa]: the symmetric part of the Love-Weber stress
  (:func:`demcli.measure.tensors.love_weber`) of the contacts of the bodies inside (each body side
  of a contact whose body is inside; the wall's side of a wall contact never: a region reaching
  a wall measures the stress the wall holds); pressure p = tr / 3 and deviator q [Pa];
* mean_coordination: mean contacts per body inside; mechanical_coordination: the same without
  the rattlers, bodies with fewer than 2 contacts removed one sweep after another over the whole
  scene (:func:`demcli.stages.packing_record.contact_counts`; fixed bodies never rattle);
  **walls count** as contacts (each wall a body touches once), a body pair touching at several
  points (clumps) is one contact, an intact bond is one; rattler_fraction: rattlers / bodies;
* fabric_xx ... fabric_yz: the fabric tensor <n (x) n> of the contact normals of the same body
  sides as the stress (a clump's member contacts one by one); anisotropy a; fabric_f_* and
  anisotropy_f: the same weighted by |F_n| (:func:`demcli.measure.tensors.fabric`);
* velocity_x, velocity_y, velocity_z [m/s]: the bodies' mass-weighted mean velocity; velocity_rms
  [m/s]: the rms of their fluctuation about it.

An empty region gives NaN means and 0 bodies.
"""

import math
from types import SimpleNamespace

import numpy as np

from demcli.errors import InputError
from demcli.measure.contacts import contact_set
from demcli.measure.regions import Region
from demcli.measure.tensors import (anisotropy, fabric, invariants, love_weber, sides, symmetric_columns,
                                    velocity_stats)
from demcli.state.records import describe_column

PAIRS = ("xx", "yy", "zz", "xy", "xz", "yz")
COLUMNS = {"time": "s", "step": "1", "bodies": "1", "volume": "m^3", "solid_fraction": "1",
           **{f"sigma_{c}": "Pa" for c in PAIRS}, "pressure": "Pa", "deviator": "Pa",
           "mean_coordination": "1", "mechanical_coordination": "1", "rattler_fraction": "1",
           **{f"fabric_{c}": "1" for c in PAIRS}, "anisotropy": "1",
           **{f"fabric_f_{c}": "1" for c in PAIRS}, "anisotropy_f": "1",
           "velocity_x": "m/s", "velocity_y": "m/s", "velocity_z": "m/s", "velocity_rms": "m/s"}
MIN_CONTACTS = 2
"""A body with fewer contacts (bodies and walls) is a rattler."""

for _c in PAIRS:
    describe_column(f"sigma_{_c}", f"Stress {_c}", "Pa", "kPa", 1e-3,
                    doc=f"Love-Weber stress component {_c} of a measurement region (compression positive)")
    describe_column(f"fabric_{_c}", f"Fabric {_c}", doc=f"component {_c} of the fabric tensor <n (x) n>")
    describe_column(f"fabric_f_{_c}", f"Force-weighted fabric {_c}",
                    doc=f"component {_c} of the fabric tensor weighted by the normal force magnitude")
for _name, _label, _unit, _display, _scale, _doc in (
        ("volume", "Region volume", "m^3", "cm^3", 1e6, "volume of the measurement region"),
        ("pressure", "Mean stress", "Pa", "kPa", 1e-3, "p = tr(sigma) / 3 of the Love-Weber stress (compression "
                                                       "positive)"),
        ("deviator", "Deviator stress", "Pa", "kPa", 1e-3, "q = sqrt(3/2 s:s), s the deviatoric stress"),
        ("mean_coordination", "Mean coordination", "1", None, 1.0, "contacts (bodies and walls) per body whose "
                                                                   "centre lies in the region"),
        ("mechanical_coordination", "Mechanical coordination", "1", None, 1.0,
         "contacts per body in the region, rattlers (< 2 contacts, removed iteratively) excluded"),
        ("anisotropy", "Fabric anisotropy", "1", None, 1.0, "a = sqrt(3/2 a:a), a = 15/2 dev(fabric) (a_1 - a_3 "
                                                            "when axisymmetric)"),
        ("anisotropy_f", "Force-weighted fabric anisotropy", "1", None, 1.0,
         "anisotropy of the fabric weighted by |F_n|"),
        ("velocity_x", "Mean velocity x", "m/s", None, 1.0, "mass-weighted mean velocity of the bodies in a region"),
        ("velocity_y", "Mean velocity y", "m/s", None, 1.0, "mass-weighted mean velocity of the bodies in a region"),
        ("velocity_z", "Mean velocity z", "m/s", None, 1.0, "mass-weighted mean velocity of the bodies in a region"),
        ("velocity_rms", "Velocity fluctuation", "m/s", None, 1.0, "rms of the bodies' velocity about the mean")):
    describe_column(_name, _label, _unit, _display, _scale, doc=_doc)


def check_scene(system, planar):
    """InputError for a scene the measures cannot take: spheres with polyhedra; a 2D case when
    ``planar`` (regions and fields are per volume)."""
    if system.plugin.name not in ("spheres", "polyhedra"):
        raise InputError(f"measure: the measures (regions, force chains, fields) are for sphere, clump and polyhedron "
                         f"scenes; this one has {system.plugin.name} bodies (spheres with polyhedra)")
    if planar:
        raise InputError("measure: the measurement regions and coarse-grained fields are 3D (per volume); this case "
                         "is planar")


class MeasureProbe:
    """The row of each measurement region of a system at a record.

    Args:
        system: the stage's :class:`~demcli.engine.system.System` (spheres, clumps or polyhedra).
        specs: the validated ``measure:`` entries.
    """

    def __init__(self, system, specs):
        from demcli.kernels.layout import FIX_TRANSLATION
        from demcli.stages.packing_record import PackingProbe

        self.regions = [Region(s) for s in specs]
        self.held = (np.asarray(system.bflags) & FIX_TRANSLATION) != 0
        arounds = {"bodies"} | {r.spec.around for r in self.regions if r.kind == "all"}
        self.boxes = {around: PackingProbe(system, SimpleNamespace(window=None, margin=0.0, around=around,
                                                                   min_contacts=MIN_CONTACTS), False, 1.0, 0.0)
                      for around in sorted(arounds)}
        geo = self.boxes["bodies"]
        if geo.poly:
            self.body_volume = np.array([geo.templates[k][4] for k in geo.shape])
        else:
            self.body_volume = geo.body_volume

    def rows(self, system, contacts=None):
        """{region name: row} of the system now (``contacts``: its ContactSet, when already built)."""
        from demcli.stages.packing_record import PackingProbe, contact_counts

        contacts = contact_set(system) if contacts is None else contacts
        x = np.asarray(system.x)
        sd = sides(contacts, x)
        fn = np.abs(contacts.normal_force())[sd.contact]
        pairs, walls = PackingProbe.body_contacts(system)
        z0, z, rattler = contact_counts(len(x), pairs, walls, MIN_CONTACTS, self.held)
        out = {}
        for region in self.regions:
            row = {"time": system.time, "step": system.step}
            if region.kind == "all":
                region.set_box(*self.boxes[region.spec.around].bounds(system))
            inside = region.inside(x)
            volume = region.volume()
            row.update(bodies=int(inside.sum()), volume=volume, solid_fraction=self._solid(system, region, inside,
                                                                                            volume))
            sel = inside[sd.body]
            sigma = love_weber(sd.branch[sel], sd.force[sel], volume)
            row.update(symmetric_columns("sigma", sigma))
            row["pressure"], row["deviator"] = invariants(sigma)
            row.update(_coordination(inside, z0, z, rattler))
            phi, phi_f = fabric(sd.normal[sel]), fabric(sd.normal[sel], fn[sel])
            row.update(symmetric_columns("fabric", phi), anisotropy=anisotropy(phi))
            row.update(symmetric_columns("fabric_f", phi_f), anisotropy_f=anisotropy(phi_f))
            mean, rms = velocity_stats(np.asarray(system.mass)[inside], np.asarray(system.v)[inside])
            row.update(velocity_x=float(mean[0]), velocity_y=float(mean[1]), velocity_z=float(mean[2]),
                       velocity_rms=rms)
            out[region.name] = row
        return out

    def _solid(self, system, region, inside, volume):
        """Solid fraction of a region: exact in a box, the centre-count estimate otherwise."""
        if volume <= 0.0:
            return math.nan
        if region.box is not None:
            return self.boxes["bodies"].solid_volume(system, *region.box) / volume
        return float(np.sum(self.body_volume[inside])) / volume


def _coordination(inside, z0, z, rattler):
    """The coordination columns of the bodies ``inside`` from the scene's contact counts."""
    n = int(inside.sum())
    kept = inside & ~rattler
    return {"mean_coordination": float(z0[inside].mean()) if n else math.nan,
            "mechanical_coordination": float(z[kept].mean()) if kept.any() else math.nan,
            "rattler_fraction": float((inside & rattler).sum()) / n if n else math.nan}
