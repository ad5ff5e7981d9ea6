"""Coarse-grained continuum fields on a regular grid (``output.fields`` of a dem stage).

At every snapshot, on the grid points r of a box (``min``..``max``, default the bodies' bounding
box) ``spacing`` apart (default the kernel width w), with the kernel phi of
:mod:`demcli.measure.cg_kernels` (Goldhirsch 2010; Weinhart et al. 2012):

* density rho(r) = sum_b m_b phi(r - x_b) [kg/m^3]; momentum p(r) = sum_b m_b v_b phi(r - x_b)
  [kg/(m^2 s)]; velocity V = p / rho [m/s] (0 where rho = 0);
* kinetic stress sigma^k = sum_b m_b v'_b (x) v'_b phi(r - x_b), v'_b = v_b - V(r), computed as
  sum m v (x) v phi - rho V (x) V [Pa];
* contact stress sigma^c = sum over the body sides of the contacts of (x_b - x_c) (x) f_b times
  phi integrated along the segment from the body's centre to the contact point [Pa] (a pair:
  the whole branch line; a wall contact: the body's half);
* stress sigma = sigma^k + sigma^c, compression positive like the region records; pressure
  tr(sigma) / 3 and deviator q = sqrt(3/2 s:s) [Pa].

Masses are the real ones (a mass-scaled stage divides its scaling out). Written as
``<stage>/fields_NNNNNN.vtu`` (hexahedral cells between the grid points, point data ``density``,
``momentum``, ``velocity``, ``stress``, ``kinetic_stress``, ``contact_stress`` (9 components,
row-major), ``pressure``, ``deviator``) with the series ``fields.pvd``.
"""

from pathlib import Path
from typing import NamedTuple

import meshio
import numpy as np

from demcli.errors import InputError
from demcli.measure.contacts import contact_set
from demcli.measure.tensors import sides
from demcli.state.vtu import PvdSeries, _write_mesh

MAX_POINTS = 2_000_000
"""Largest grid (points) a stage writes."""


class Grid(NamedTuple):
    """A regular grid: lo (3,) origin [m], spacing (3,) [m], shape (3,) int points per axis;
    point i + nx (j + ny k) is at lo + (i, j, k) spacing."""

    lo: np.ndarray
    spacing: np.ndarray
    shape: np.ndarray

    def points(self):
        """(p, 3) the grid points [m], x fastest."""
        axes = [self.lo[d] + self.spacing[d] * np.arange(self.shape[d]) for d in range(3)]
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def make_grid(lo, hi, spacing):
    """The Grid from lo to (at least) hi [m] with about ``spacing`` [m] between points: the
    spacing per axis is (hi - lo) / (points - 1) for the fewest points not wider apart; a flat
    axis has one point. InputError beyond :data:`MAX_POINTS`."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    size = np.maximum(hi - lo, 0.0)
    shape = np.maximum(np.ceil(size / spacing - 1e-9).astype(np.int64) + 1, 1)
    if int(np.prod(shape)) > MAX_POINTS:
        raise InputError(f"output.fields: a grid of {' x '.join(map(str, shape))} points is more than {MAX_POINTS}; "
                         f"use a larger spacing than {spacing:g} m or a smaller box")
    step = np.where(shape > 1, size / np.maximum(shape - 1, 1), spacing)
    return Grid(lo, step, shape)


def coarse_fields(grid, x, mass, v, start, end, force, width, kernel="gaussian"):
    """The fields of the module doc on ``grid``: {name: (p,) or (p, 3) or (p, 9) array}.

    Args: x (n, 3) [m], mass (n,) [kg], v (n, 3) [m/s] of the bodies; start, end (m, 3) [m] the
    body centre and contact point of each body side of the contacts and force (m, 3) [N] on the
    body; width w [m]; kernel "gaussian" or "lucy".
    """
    from demcli.measure.cg_kernels import KERNELS, contact_stress, point_fields

    kind = KERNELS[kernel]
    args = (np.ascontiguousarray(grid.lo, float), np.ascontiguousarray(grid.spacing, float),
            np.ascontiguousarray(grid.shape, np.int64))
    f64 = [np.ascontiguousarray(a, float).reshape(-1, k) for a, k in ((x, 3), (v, 3), (start, 3), (end, 3),
                                                                      (force, 3))]
    rho, mom, mvv = point_fields(*args, f64[0], np.ascontiguousarray(mass, float), f64[1], float(width), kind)
    contact = contact_stress(*args, f64[2], f64[3], f64[4], float(width), kind)
    vel = np.divide(mom, rho[:, None], out=np.zeros_like(mom), where=rho[:, None] > 0.0)
    kinetic = mvv - rho[:, None] * np.einsum("pi,pj->pij", vel, vel).reshape(-1, 9)
    stress = kinetic + contact
    t = stress.reshape(-1, 3, 3)
    sym = 0.5 * (t + np.transpose(t, (0, 2, 1)))
    pressure = np.trace(sym, axis1=1, axis2=2) / 3.0
    dev = sym - pressure[:, None, None] * np.eye(3)
    return {"density": rho, "momentum": mom, "velocity": vel, "stress": stress, "kinetic_stress": kinetic,
            "contact_stress": contact, "pressure": pressure,
            "deviator": np.sqrt(1.5 * np.einsum("pij,pij->p", dev, dev))}


def grid_mesh(grid, point_data):
    """meshio Mesh of the grid's points and the hexahedra between them, with ``point_data``."""
    nx, ny, nz = (int(n) for n in grid.shape)
    idx = np.arange(nx * ny * nz).reshape(nz, ny, nx)
    if min(nx, ny, nz) < 2:
        return meshio.Mesh(grid.points(), [("vertex", idx.reshape(-1, 1))], point_data=point_data)
    c = idx[:-1, :-1, :-1].ravel()
    dx, dy, dz = 1, nx, nx * ny
    hexa = np.stack([c, c + dx, c + dx + dy, c + dy, c + dz, c + dx + dz, c + dx + dy + dz, c + dy + dz], axis=1)
    return meshio.Mesh(grid.points(), [("hexahedron", hexa)], point_data=point_data)


class FieldSeries:
    """The ``fields`` series of a stage folder for a validated ``output.fields`` section."""

    def __init__(self, folder, spec, resume=False):
        self.folder = Path(folder)
        self.spec = spec
        self.series = PvdSeries(self.folder / "fields.pvd", resume=resume)

    def grid(self, system):
        """The grid now: the configured box, else the bodies' bounding box (centres +- radius)."""
        s = self.spec
        if s.min is not None:
            lo, hi = np.array(s.min, float), np.array(s.max, float)
        else:
            from demcli.stages.loop import body_radii

            reach = body_radii(system)[:, None]
            lo, hi = np.min(system.x - reach, axis=0), np.max(system.x + reach, axis=0)
        return make_grid(lo, hi, s.spacing if s.spacing is not None else s.width)

    def write(self, system, contacts=None):
        """Write the fields now as the series' next snapshot; returns the path."""
        contacts = contact_set(system) if contacts is None else contacts
        x = np.asarray(system.x)
        sd = sides(contacts, x)
        grid = self.grid(system)
        data = coarse_fields(grid, x, np.asarray(system.mass) / system.mass_scale, system.v, x[sd.body],
                             x[sd.body] - sd.branch, sd.force, self.spec.width, self.spec.kernel)
        self.folder.mkdir(parents=True, exist_ok=True)
        path = _write_mesh(self.folder / f"fields_{len(self.series):06d}.vtu", grid_mesh(grid, data))
        self.series.add(system.time, path)
        return path

    def truncate(self, time):
        """Drop the entries after ``time`` (a resumed stage)."""
        self.series.truncate(time)
