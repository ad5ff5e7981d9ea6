"""The force network as VTU line cells (``output.force_chains``), for ParaView beside the
particle snapshots.

At every snapshot ``<stage>/force_chains_NNNNNN.vtu`` (the number of the particle snapshot
written with it) and the series ``force_chains.pvd``. One line cell per contact
(:func:`demcli.measure.contacts.contact_set`): body centre to body centre for a pair, body centre
to the contact point for a wall contact. Cell data: ``normal_force`` [N] (F . n, > 0 pushing
apart), ``tangential_force`` [N] (magnitude), ``overlap`` [m], ``bond_state`` (-1 a contact, 0 an
intact bond, 1 / 2 a bond broken in tension / shear, still seated) and ``wall`` (the wall index,
-1 for a pair). Each line has its own two points, with point data ``body_id`` (the body at that
end, -1 on a wall), ``normal_force`` and ``tangential_force`` (the line's, at both ends). In
ParaView: colour by ``normal_force``, or *Extract Surface* then *Tube* with Vary Radius By Scalar
``normal_force`` (docs/measure.md).
"""

from pathlib import Path

import meshio
import numpy as np

from demcli.measure.contacts import contact_set
from demcli.state.vtu import PvdSeries, _write_mesh


def force_chain_mesh(x, body_id, contacts):
    """The meshio Mesh of the contacts (a ContactSet) of bodies at ``x`` (n, 3) [m] with ids
    ``body_id`` (see the module doc). Each line has its own two points (so that ParaView's *Tube*
    can vary its radius by the point copy of the contact's normal force)."""
    x = np.asarray(x, float).reshape(-1, 3)
    k = len(contacts.a)
    pair = contacts.b >= 0
    far = np.where(pair[:, None], x[np.where(pair, contacts.b, 0)], contacts.point)
    points = np.stack([x[contacts.a], far], axis=1).reshape(-1, 3)
    lines = np.arange(2 * k, dtype=np.int64).reshape(-1, 2)
    fn, ft = contacts.normal_force(), contacts.tangential_force()
    cell_data = {"normal_force": [fn], "tangential_force": [ft], "overlap": [np.asarray(contacts.overlap, float)],
                 "bond_state": [contacts.bond.astype(np.int64)], "wall": [contacts.wall.astype(np.int64)]}
    ids = np.asarray(body_id, np.int64)
    ends = np.stack([ids[contacts.a], np.where(pair, ids[np.where(pair, contacts.b, 0)], -1)], axis=1).reshape(-1)
    point_data = {"body_id": ends, "normal_force": np.repeat(fn, 2), "tangential_force": np.repeat(ft, 2)}
    return meshio.Mesh(points, [("line", lines)], point_data=point_data, cell_data=cell_data)


class ForceChains:
    """The ``force_chains`` series of a stage folder; ``resume``: keep the existing entries."""

    def __init__(self, folder, resume=False):
        self.folder = Path(folder)
        self.series = PvdSeries(self.folder / "force_chains.pvd", resume=resume)

    def write(self, system, contacts=None):
        """Write the system's contact network now as the series' next snapshot (numbered as the
        particle snapshot written with it); returns the path."""
        number = len(self.series)
        contacts = contact_set(system) if contacts is None else contacts
        self.folder.mkdir(parents=True, exist_ok=True)
        path = _write_mesh(self.folder / f"force_chains_{number:06d}.vtu",
                           force_chain_mesh(system.x, system.body_id, contacts))
        self.series.add(system.time, path)
        return path

    def truncate(self, time):
        """Drop the entries after ``time`` (a resumed stage)."""
        self.series.truncate(time)
