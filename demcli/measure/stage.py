"""What the dem stage loop (:func:`demcli.stages.loop.integrate`) calls for the measures a stage
asks for: the ``measure:`` regions at every record row, and at every snapshot the force network
(``output.force_chains``) and the coarse-grained fields (``output.fields``). A stage that asks
for none of them gets None from :meth:`StageMeasures.make` and runs as before.
"""

from demcli.measure.coarse import FieldSeries
from demcli.measure.contacts import contact_set
from demcli.measure.figure import write_region_figure
from demcli.measure.forcechain import ForceChains
from demcli.measure.probe import COLUMNS, MeasureProbe, check_scene
from demcli.state.records import RecordTable


class StageMeasures:
    """The measures of one stage run.

    Args:
        ctx: the stage context (``snapshot_dir``, ``runner.run_dir``, ``name``).
        cfg: the stage's validated config.
        system: its System.
        ckpt: the checkpoint State it resumes from, or None.
        planar: a 2D case.
    """

    def __init__(self, ctx, cfg, system, ckpt, planar):
        specs = cfg.get("measure") or ()
        out = cfg.output
        resume = ckpt is not None
        per_volume = bool(specs) or out.get("fields") is not None
        if per_volume or out.get("force_chains"):
            check_scene(system, planar and per_volume)  # a planar network is lines as any other
        self.probe = MeasureProbe(system, specs) if specs else None
        self.tables = [RecordTable.from_state(ckpt, f"measure_{s.name}") if resume else
                       RecordTable(f"measure_{s.name}", COLUMNS) for s in specs]
        self.chains = ForceChains(ctx.snapshot_dir, resume) if out.get("force_chains") else None
        self.fields = FieldSeries(ctx.snapshot_dir, out.fields, resume) if out.get("fields") is not None else None
        self._cache = (None, None)

    @classmethod
    def make(cls, ctx, cfg, system, ckpt, planar):
        """The stage's StageMeasures, or None when its config asks for no measure."""
        out = cfg.output
        if not (cfg.get("measure") or out.get("force_chains") or out.get("fields") is not None):
            return None
        return cls(ctx, cfg, system, ckpt, planar)

    def _contacts(self, system):
        """The ContactSet now, built once per step (a record and a snapshot share it)."""
        key = (system.step, system.time)
        if self._cache[0] != key:
            self._cache = (key, contact_set(system))
        return self._cache[1]

    def record(self, system):
        """One row into each region's table."""
        if self.probe is None:
            return
        rows = self.probe.rows(system, self._contacts(system))
        for table, region in zip(self.tables, self.probe.regions):
            table.append(rows[region.name])

    def snapshot(self, system):
        """The force network and the fields now, numbered as the particle snapshot."""
        if self.chains is not None:
            self.chains.write(system, self._contacts(system))
        if self.fields is not None:
            self.fields.write(system, self._contacts(system))

    def truncate(self, time):
        """Drop the snapshots after ``time`` (a resumed stage)."""
        for series in (self.chains, self.fields):
            if series is not None:
                series.truncate(time)

    def write(self, ctx, state):
        """The region tables into ``state`` and as CSV + PNG in records/: the mean stress and
        deviator (``<stage>_measure_<name>.png``) and the four panels (``..._panels.png``)."""
        for table in self.tables:
            table.to_state(state)
            ctx.write_records(table, x="time", ys=["pressure", "deviator"])
            write_region_figure(table, ctx.runner.run_dir / "records" / f"{ctx.name}_{table.name}_panels.png",
                                title=f"{ctx.runner.name}: {ctx.name}, region {table.name[len('measure_'):]}")
