"""Run a case: its stages in order, each reading the previous stage's state.

Outputs of a case live in one run folder (default ``runs/<case name>``)::

    <NN>-<stage>.h5              the stage's state (atomic write)
    <NN>-<stage>.ckpt.h5         checkpoint of an interrupted stage (``--resume``)
    <NN>-<stage>.lastgood.h5     last good state of a stage stopped by a guard
    <stage>/spheres.pvd, *.vtu   snapshots for ParaView
    records/<stage>_<table>.csv  records, with PNG plots
    log.txt                      one line per event, with wall time and throughput

A stage is skipped when its state exists and records the same stage config hash and
the same input-state hash (so editing one stage re-runs it and everything after it).
"""

import contextlib
import difflib
import errno
import os
import sys
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from demcli.errors import InputError, StageError, StateError, WriteError
from demcli.progress import Progress


def _read_only(folder):
    """Whether ``folder`` lies on a file system mounted read-only."""
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _reason(exc, path):
    """A StateError's message without the file name it starts with."""
    return exc.format_message().removeprefix(f"{path}: ")


@dataclass
class StageResult:
    name: str
    path: Path
    skipped: bool
    wall_time: float
    throughput: float = 0.0


class StageContext:
    """What a stage's run function may use: identity, RNG, logging and output helpers."""

    def __init__(self, runner, index, cfg, config_hash, input_hash):
        self.runner = runner
        self.case = runner.case
        self.index = index
        self.name = cfg.name
        self.type = cfg.type
        self.cfg = cfg
        self.config_hash = config_hash
        self.input_hash = input_hash
        self.seed = int(self.case.seed)
        self.rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([self.seed, index])))
        self.snapshot_dir = runner.run_dir / self.name
        self.checkpoint_path = runner.run_dir / f"{index:02d}-{self.name}.ckpt.h5"
        self.lastgood_path = runner.run_dir / f"{index:02d}-{self.name}.lastgood.h5"
        self.throughput = 0.0

    # ---- logging ----
    def log(self, message):
        self.runner.log(f"[{self.name}] {message}")

    def progress(self, total, start, nparticles):
        """A :class:`Progress` for steps ``start``..``total`` of ``nparticles`` particles (the system
        being stepped, as the stage's closing throughput line counts them)."""
        return Progress(self.name, total, start, self.runner.quiet, nparticles)

    # ---- states ----
    def new_state(self, effects=(), time=0.0, step=0, dt=0.0):
        from demcli.state import new_state

        return new_state(self.name, self.type, dim=int(self.case.dimension), seed=self.seed,
                         case_file=str(self.runner.case_path), case_hash=self.runner.case_hash,
                         config_hash=self.config_hash, input_hash=self.input_hash, effects=sorted(effects),
                         time=time, step=step, dt=dt)

    def state_from(self, system, plan, extra=None):
        """A State of the system's current scene (plus ``extra`` groups)."""
        st = self.new_state(effects=plan.effects, time=system.time, step=system.step, dt=system.dt)
        st.groups.update(system.groups())
        if extra:
            st.groups.update(extra)
        return st

    def load_checkpoint(self):
        """The checkpoint of this stage when resuming and it matches this config and input;
        None otherwise (an unreadable checkpoint is logged: the stage starts afresh)."""
        from demcli.state import read_state

        if not self.runner.resume or not self.checkpoint_path.exists():
            return None
        try:
            st = read_state(self.checkpoint_path)
        except StateError as exc:
            self.log(f"checkpoint {self.checkpoint_path.name} is unreadable ({_reason(exc, self.checkpoint_path)}); "
                     "starting the stage afresh")
            return None
        if st.meta.get("config_hash") != self.config_hash or st.meta.get("input_hash") != self.input_hash:
            self.log("checkpoint is from another config or input; starting the stage afresh")
            return None
        at = f"step {int(st.meta.get('step', 0))}"
        if "time" in st.meta:
            at += f" (t = {float(st.meta['time']):.6g} s)"
        self.log(f"resuming from {self.checkpoint_path.name} at {at}")
        return st

    def write_checkpoint(self, state):
        from demcli.state import set_rng, write_state

        set_rng(state, self.rng)
        self.runner.finish_state(state)
        write_state(self.checkpoint_path, state)
        self.log(f"checkpoint written: {self.checkpoint_path}")
        return self.checkpoint_path

    def fail(self, message, system, plan, last_good):
        """Write the last good state and stop the stage with ``message``."""
        from demcli.state import write_state

        system.restore(last_good)
        st = self.state_from(system, plan)
        self.runner.finish_state(st)
        write_state(self.lastgood_path, st)
        raise StageError(message, state_file=self.lastgood_path)

    def write_records(self, table, x=None, ys=(), logy=False, suffix=None, logx=False, figure=None, **style):
        """CSV of a record table and a PNG of ``ys`` against ``x`` in ``records/`` (``style``:
        more :meth:`RecordTable.figure` keywords, e.g. ``targets``, ``xlabel``); ``figure``: a
        matplotlib Figure the stage drew (or None without matplotlib) instead of that plot."""
        folder = self.runner.run_dir / "records"
        folder.mkdir(parents=True, exist_ok=True)
        stem = f"{self.name}_{table.name}"
        table.write_csv(folder / f"{stem}.csv")
        png = folder / f"{stem}{'_' + suffix if suffix else ''}.png"
        if x is None:
            from demcli.state.plots import save_png

            save_png(figure, png)
            return
        table.plot(png, x, ys, logx=logx, logy=logy, title=f"{self.runner.name}: {self.name}", **style)


class Runner:
    """Runs the stages of one validated case."""

    def __init__(self, case_path, overrides=(), out=None, quiet=False, resume=False):
        from demcli.config.schema import sha256_of
        from demcli.stages.base import load_case

        self.case_path = Path(case_path)
        self.case = load_case(case_path, overrides)
        self.name = self.case.name or self.case_path.stem
        self.run_dir = Path(out) if out else Path("runs") / self.name
        self.quiet = quiet
        self.resume = resume
        self.case_hash = sha256_of(self.case.to_dict())
        self._shared = {k: self.case[k] for k in ("seed", "dimension", "thickness")}
        self._shared["materials"] = self.case.materials.to_dict()
        self._logfile = None
        self.threads = 1

    def log(self, message):
        line = f"{_time.strftime('%H:%M:%S')} {message}"
        if not self.quiet:
            print(line, file=sys.stderr, flush=True)
        if self._logfile is not None:
            try:
                self._logfile.write(line + "\n")
                self._logfile.flush()
            except OSError as exc:
                self._close_log()  # nothing more goes to a file that cannot be written
                if not WriteError.is_disk_error(exc):
                    raise
                raise WriteError(self.run_dir / "log.txt", exc) from None

    def _open_log(self):
        """The run folder and its log.txt, opened for appending (WriteError when it cannot be)."""
        path = self.run_dir / "log.txt"
        try:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            if not os.access(self.run_dir, os.W_OK):  # also a read-only mount, for root
                code = errno.EROFS if _read_only(self.run_dir) else errno.EACCES
                raise OSError(code, os.strerror(code))
            self._logfile = open(path, "a", encoding="utf-8")
        except OSError as exc:
            if not WriteError.is_disk_error(exc):
                raise
            raise WriteError(path, exc) from None

    def _close_log(self):
        logfile, self._logfile = self._logfile, None
        if logfile is not None:
            with contextlib.suppress(OSError):  # its last lines may not fit on a full disk
                logfile.close()

    def stage_index(self, name, option):
        names = [s.name for s in self.case.stages]
        if name not in names:
            close = difflib.get_close_matches(name, names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f"; stages are {', '.join(names)}"
            raise InputError(f"{option} {name}: no such stage in {self.case_path}{hint}")
        return names.index(name)

    def config_hash(self, cfg):
        from demcli.config.schema import sha256_of
        from demcli.stages.base import STAGE_TYPES

        st = STAGE_TYPES[cfg.type]
        files = st.file_digest(cfg, self.case_path.resolve().parent) if st.file_digest is not None else None
        return sha256_of({"stage": cfg.to_dict(), "case": self._shared, **({"files": files} if files else {})})

    def finish_state(self, state):
        """Materials of the case into a state about to be written."""
        names = list(self.case.materials)
        mats = self.case.materials
        state.groups["materials"] = {
            "name": np.array(names, dtype=object),
            **{k: np.array([mats[n][k] for n in names], float)
               for k in ("density", "young", "poisson", "friction", "rolling_friction", "restitution")},
            "shear": np.array([mats[n]["young"] / (2 * (1 + mats[n]["poisson"])) if mats[n]["shear"] is None
                               else mats[n]["shear"] for n in names], float)}

    def output_path(self, k):
        return self.run_dir / f"{k:02d}-{self.case.stages[k].name}.h5"

    def _stopped(self, ctx, message):
        """A StageError for a stage that stops, also in the log (a batch job's stderr may be lost)."""
        exc = StageError(message)
        self.log(f"[{ctx.name}] {exc.format_message()}")
        return exc

    def _run_stage(self, ctx, st_type, state_in, out_path):
        """Run one stage and write its state; returns (state, StageResult).

        Ctrl-C or SIGTERM while the stage runs stops it (a stepping stage keeps a checkpoint
        for ``--resume``; others start again from their input); one that comes while its state
        is written waits for the write, and the run stops right after it.
        """
        from demcli import interrupts
        from demcli.state import set_rng, write_state

        self.log(f"[{ctx.name}] {ctx.type} stage started")
        t0 = _time.perf_counter()
        try:
            state = st_type.run(ctx, ctx.cfg, state_in)
        except StageError as exc:
            self.log(f"[{ctx.name}] {exc.format_message()}")
            raise
        except KeyboardInterrupt:
            raise self._stopped(ctx, f"stage {ctx.name} interrupted; run the case again to redo it, with --resume "
                                     "to continue from its checkpoint if it wrote one") from None
        try:
            with interrupts.deferred() as poll:
                set_rng(state, ctx.rng)
                self.finish_state(state)
                write_state(out_path, state)
                if ctx.checkpoint_path.exists():
                    ctx.checkpoint_path.unlink()
                wall = _time.perf_counter() - t0
                self.log(f"[{ctx.name}] done in {wall:.2f} s"
                         + (f", {ctx.throughput:.3g} particle-steps/s" if ctx.throughput else "")
                         + f" -> {out_path.name}")
                poll()
        except KeyboardInterrupt:
            raise self._stopped(ctx, f"interrupted after stage {ctx.name} finished ({out_path.name} written); run the "
                                     "case again to go on with the next stages") from None
        return state, StageResult(ctx.name, out_path, False, wall, ctx.throughput)

    def _up_to_date(self, name, out_path, config_hash, input_hash):
        """The state of a stage whose output records the same config and input hashes, read
        whole (checksums, value rules) and kept as the next stage's input; None when the stage
        must run, also when its output is unreadable (logged: the stage is recomputed)."""
        from demcli.state import read_meta, read_state

        try:
            meta = read_meta(out_path)
            if meta.get("config_hash") != config_hash or meta.get("input_hash") != input_hash:
                return None
            return read_state(out_path)
        except StateError as exc:
            self.log(f"[{name}] state {out_path.name} is unreadable ({_reason(exc, out_path)}); recomputing the stage")
            return None

    def run(self, from_stage=None, only=None, force=False):
        from demcli.stages.base import STAGE_TYPES, load_stage_types
        from demcli.state import read_state, require, state_hash
        from demcli.state.order import spatial_order

        load_stage_types()
        stages = self.case.stages
        first = self.stage_index(from_stage, "--from") if from_stage else 0
        only_k = self.stage_index(only, "--only") if only else None
        self._open_log()
        results = []
        try:
            self.log(f"case {self.case_path} -> {self.run_dir} ({self.threads} thread{'s' if self.threads > 1 else ''})")
            state_in, in_path = None, None
            for k, cfg in enumerate(stages):
                out_path = self.output_path(k)
                st_type = STAGE_TYPES[cfg.type]
                selected = (only_k is None and k >= first) or only_k == k
                if not selected:
                    in_path = out_path
                    state_in = None
                    continue
                moved = False
                if st_type.reads_input(cfg):  # (validation refuses a first stage that needs an input)
                    if in_path is None or not in_path.exists():
                        raise InputError(f"stage {cfg.name}: missing stage input {in_path}; run the earlier "
                                         "stages first (without --from/--only)")
                    if state_in is None:
                        state_in = read_state(in_path)
                    require(state_in, st_type.requires, consumer=f"stage {cfg.name}", source=in_path)
                    if st_type.orders_particles:  # hashed after: a checkpoint or an output made
                        state_in, moved = spatial_order(state_in)  # in another order never matches
                    input_hash = state_hash(state_in)
                else:
                    input_hash = ""
                chash = self.config_hash(cfg)
                forced = force or (from_stage is not None and k >= first) or only_k == k
                done = None
                if not forced and out_path.exists():
                    done = self._up_to_date(cfg.name, out_path, chash, input_hash)
                if done is not None:
                    self.log(f"[{cfg.name}] up to date ({out_path.name}); skipped")
                    results.append(StageResult(cfg.name, out_path, True, 0.0))
                    state_in, in_path = done, out_path
                    continue
                if moved:
                    self.log(f"[{cfg.name}] particles stored in cell order (neighbours close in memory)")
                ctx = StageContext(self, k, cfg, chash, input_hash)
                state, result = self._run_stage(ctx, st_type, state_in, out_path)
                results.append(result)
                state_in, in_path = state, out_path
                if only_k is not None:
                    break
        finally:
            self._close_log()
        return results


def run_case(case, out=None, from_stage=None, only=None, force=False, overrides=(), threads=None, quiet=False,
             resume=False):
    """Run a case file like ``demcli run``; returns a list of :class:`StageResult`.

    Args:
        case: path of the YAML case.
        out: run folder (default ``runs/<case name>``).
        from_stage: re-run from this stage on. only: run just this stage.
        force: re-run every stage even when up to date.
        overrides: ``["path=value", ...]`` applied to the case before validation.
        threads: threads for the parallel kernels (default: all cores).
        quiet: no progress or log lines on stderr.
        resume: continue interrupted stages from their checkpoints.
    """
    from demcli.jit import set_threads

    runner = Runner(case, overrides=overrides, out=out, quiet=quiet, resume=resume)
    used = set_threads(threads)
    runner.threads = used
    return runner.run(from_stage=from_stage, only=only, force=force)
