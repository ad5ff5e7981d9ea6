"""``demcli sweep``: many runs (cases, seeds, parameter values) on a Dask cluster.

A sweep file lists runs, each a case plus ``--set``-style overrides, with two generators
that expand to a grid: ``seeds: [1, 2, 3]`` (the case's top-level ``seed``) and
``vary: {path: [v1, v2]}`` (every combination; the first path changes slowest, seeds
fastest; a path written ``+path`` pairs its values with the path before it, as ``demcli study
--vary +PATH`` does). It also names the metrics to gather (``STAGE.TABLE.COLUMN[@REDUCER]``, read as
``demcli study`` reads them) and, optionally, the output folder and the cluster::

    out: sweeps/beads_seeds           # default sweeps/<sweep file name>; --out wins
    metrics: [settle.dem.kinetic@last, settle.dem.coordination@last]
    set: {stages.settle.time.steps: 1000}      # applied to every run
    seeds: [1, 2, 3]                  # default for runs that give none
    runs:
      - case: ../smoke/beads.yaml     # relative to the sweep file
        vary: {stages.settle.time.dt_factor: [0.25, 0.1]}
      - {case: ../smoke/planar.yaml, name: planar, seeds: {first: 1, count: 10}}
    cluster: {type: local, workers: 2, threads_per_run: 1}

Outputs (``--out``)::

    <out>/<run name>/<grid point>/    one run folder per run, as ``demcli run --out`` writes it,
                                      plus sweep.log (the command, its exit code and output)
    <out>/sweep.csv                   one row per run: overrides, metrics, status, wall time
    <out>/status.csv                  run, case, status, wall time, folder

The sweep file is validated with the case machinery (:mod:`demcli.config`): every problem
names file, line, key, rule and value, exit code 2, before anything runs. Each run's case
is then validated with its overrides; a run whose case is invalid is reported as failed
and not started. Valid runs go to Dask: a local cluster by default (``LocalCluster``, one
process per worker, one thread each), an existing scheduler (``--scheduler``), or a
SLURM/PBS cluster through dask-jobqueue (imported only then). A Dask task runs
``demcli run CASE --out FOLDER --set ...`` in a child Python process and reads the
metrics from its records, so a run that crashes (even a segfault) is one failed row, not
a lost worker. One failed run never stops the sweep; the exit code is 0 when every run
succeeded and 1 otherwise.
"""

from __future__ import annotations

import contextlib
import csv
import io
import logging
import math
import os
import platform
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from demcli.config import (NOVALUE, ConfigIssue, Field, Int, List, Map, Node, Optional, Section, Str, format_path,
                           load_yaml, validate)
from demcli.config.case import SEED_MAX
from demcli.errors import ConfigError, DemcliError, InputError
from demcli.state.atomic import atomic_write_text
from demcli.study import Vary, _header, _num, default_jobs, make_variants, parse_metric, read_metric

__all__ = ["SweepFileError", "SweepRun", "SweepPlan", "SweepResult", "sweep_schema", "load_sweep", "plan_sweep",
           "run_sweep", "check_sweep"]

CLUSTER_TYPES = ("local", "slurm", "pbs")
_PATH = re.compile(r"[^\s.=]+(\.[^\s.=]+)*")
_STAGE_LINE = re.compile(r"^\s*(\S+)\s+(skipped|[0-9.]+ s)\s+\S")  # `demcli run`'s stdout: one line per stage


class SweepFileError(ConfigError):
    """A sweep file that fails validation (exit 2); ``errors`` holds every problem."""

    def __init__(self, errors):
        self.errors = list(errors)
        lines = [str(e) for e in self.errors]
        head = "1 problem" if len(lines) == 1 else f"{len(lines)} problems"
        InputError.__init__(self, f"invalid sweep file ({head}):\n  " + "\n  ".join(lines))


# ---------------------------------------------------------------------------------------
# the sweep file's schema

class _Value(Field):
    """Any YAML value: an override's value, written as ``--set`` would take it."""

    type_name = "any"

    def validate(self, value, path, ctx):
        return value


class _Metric(Str):
    """``STAGE.TABLE.COLUMN[@REDUCER]``, checked by :func:`demcli.study.parse_metric`."""

    type_name = "STAGE.TABLE.COLUMN[@REDUCER]"

    def validate(self, value, path, ctx):
        out = super().validate(value, path, ctx)
        if isinstance(out, str):
            try:
                parse_metric(out)
            except InputError as exc:
                ctx.error(path, exc.format_message().replace(f"--metric {out}: ", "", 1), out)
                return None
        return out


def _seeds_fit(node, report):
    if node.first + node.count - 1 > SEED_MAX:
        report("count", f"the last seed passes {SEED_MAX} (2^63 - 1, what a state file holds)", node.count)


_SEED_LIST = List(Int(min=0, max=SEED_MAX), min_len=1)
_SEED_RANGE = Section({"first": Int(min=0, max=SEED_MAX, default=1, doc="first seed"),
                       "count": Int(min=1, doc="number of seeds")}, check=_seeds_fit)


class _Seeds(Field):
    """A list of seeds, or ``{first, count}``; a tuple of ints."""

    type_name = "list of int >= 0, or {first, count}"

    def validate(self, value, path, ctx):
        if isinstance(value, Mapping):
            node = _SEED_RANGE.validate(value, path, ctx)
            return tuple(range(node.first, node.first + node.count)) if isinstance(node, Node) else node
        return _SEED_LIST.validate(value, path, ctx)


def sweep_schema():
    """The sweep file schema (a :class:`demcli.config.Section`; keys in docs/sweep.md)."""
    overrides = Map(_Value(), default={}, doc="case path (as --set takes it) -> value")
    vary = Optional(Map(List(_Value(), min_len=1)), doc="case path -> values; every combination is a run; a +path pairs its values with the "
                                                   "path before it (one axis, as demcli study's --vary +PATH)")
    seeds = Optional(_Seeds(), doc="values of the case's top-level seed, one run each")
    run = Section({
        "case": Str(doc="case file, relative to the sweep file"),
        "name": Str(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$", default=None,
                    doc="folder of the run's grid under the output folder (default: the case file's stem)"),
        "set": overrides,
        "seeds": seeds,
        "vary": vary,
    }, doc="one case and its overrides; seeds and vary, when given, replace the top-level ones")
    cluster = Section({
        "type": Str(choices=CLUSTER_TYPES, default="local",
                    doc="local (dask LocalCluster), slurm or pbs (dask-jobqueue)"),
        "workers": Optional(Int(min=1), doc="workers (local: default the free cores // threads_per_run; "
                                            "slurm/pbs: default one per run, at most 20)"),
        "threads_per_run": Int(min=1, default=1, doc="kernel threads of each run"),
        "options": Map(_Value(), default={}, doc="keyword arguments of the Dask cluster class"),
    }, default={}, doc="where the runs go (--scheduler connects to an existing one instead)")
    return Section({
        "out": Str(default=None, doc="output folder, relative to the working folder"),
        "metrics": List(_Metric(), default=[], doc="STAGE.TABLE.COLUMN[@REDUCER] per column"),
        "set": overrides,
        "seeds": seeds,
        "vary": vary,
        "runs": List(run, min_len=1, doc="the runs"),
        "cluster": cluster,
    }, check=_check_sweep)


def _text(value):
    """YAML text of an override value, as ``--set`` reads it back (``2 mm``, ``0.1``, ``[0, 0, -9.81]``)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10 ** 9, allow_unicode=True).strip()
    return text[:-3].rstrip() if text.endswith("\n...") else text


@dataclass(frozen=True)
class _Grid:
    name: str
    fixed: dict  # path -> value text (set, merged)
    varies: list  # study.Vary with labels, seeds last
    variants: list  # study.Variant


def _grid(top, k, run):
    """The run's grid, or ``(subpath, rule, value, hint)`` issues."""
    issues = []
    fixed = {**dict(top.set), **dict(run.set)}
    seeds = run.seeds if run.seeds is not None else top.seeds
    vary = run.vary if run.vary is not None else top.vary
    vary_at = ("runs", k, "vary") if run.vary is not None else ("vary",)
    seeds_at = ("runs", k, "seeds") if run.seeds is not None else ("seeds",)
    for where, paths in ((("set",), top.set), (("runs", k, "set"), run.set), (vary_at, vary or {})):
        for p in paths:
            if not _PATH.fullmatch(str(p)):
                issues.append((where + (p,), "not a case path; write dotted keys, e.g. stages.settle.time.steps",
                               p, None))
    for p, values in (vary or {}).items():
        texts = [_text(v) for v in values]
        dup = sorted({t for t in texts if texts.count(t) > 1})
        if dup:
            issues.append((vary_at + (p,), "a value is given twice", dup[0], None))
        if p.lstrip("+") in fixed:
            issues.append((vary_at + (p,), "the path is also given in set; drop one of them", p, None))
    if seeds is not None:
        dup = sorted({x for x in seeds if list(seeds).count(x) > 1})
        if dup:
            issues.append((seeds_at, "a seed is given twice", dup[0], None))
        for where, paths in ((vary_at, vary or {}), (("set",), fixed)):
            if "seed" in paths:
                issues.append((seeds_at, f"seed is also given in {'vary' if where == vary_at else 'set'}; "
                                         "drop one of them", NOVALUE, None))
    if issues:
        return issues
    varies = [Vary(p.lstrip("+"), tuple(_text(v) for v in values), along=p.startswith("+"))  # +path: joins the one before
              for p, values in (vary or {}).items()]
    if seeds is not None:
        varies.append(Vary("seed", tuple(str(x) for x in seeds)))
    name = _run_name(run)
    if not varies:
        return _Grid(name, {p: _text(v) for p, v in fixed.items()}, [], [])
    try:
        varies, variants = make_variants(varies)
    except InputError as exc:
        return [(vary_at, exc.format_message(), NOVALUE, None)]
    return _Grid(name, {p: _text(v) for p, v in fixed.items()}, varies, variants)


def _check_sweep(node, report):
    """Cross-field rules: generator conflicts, and one folder per run."""
    names = {}
    for k, run in enumerate(node.runs):
        grid = _grid(node, k, run)
        if not isinstance(grid, _Grid):
            for sub, rule, value, hint in grid:
                report(sub, rule, value, hint)
        name = _run_name(run)
        if name in names:
            report(("runs", k, "name" if run.name else "case"),
                   f"run folder {name!r} is also used by runs[{names[name]}]", name, "give each run a distinct name")
        names.setdefault(name, k)


def _run_name(run):
    """The run's folder under the output folder: its ``name``, else its case file's stem."""
    return run.name or Path(run.case).stem


def load_sweep(path):
    """``(node, marks)``: the validated sweep file and the line of each key;
    :class:`SweepFileError` listing every problem."""
    def reword(issues):
        return [ConfigIssue(i.file, i.line, i.path, i.rule.replace("the case is empty", "the sweep file is empty")
                            .replace("not a case file", "not a sweep file"), i.value, i.hint) for i in issues]

    try:
        data, marks = load_yaml(Path(path))
        return validate(data, marks, sweep_schema(), str(path)), marks
    except SweepFileError:
        raise
    except ConfigError as exc:
        raise SweepFileError(reword(exc.errors)) from None


# ---------------------------------------------------------------------------------------
# the runs

@dataclass
class SweepRun:
    """One run: its id (``name/grid point``), case, overrides, folder and, after the sweep, its outcome."""

    id: str
    case: str  # as written in the sweep file
    case_path: Path  # resolved
    columns: dict  # override path -> value text (set, vary, seed)
    folder: Path
    problem: str = ""  # the case fails validation with these overrides: not run
    stages: tuple = ()  # the case's stage names (when valid)
    status: str = "not run"
    wall_time: float = math.nan
    metrics: dict = field(default_factory=dict)  # metric text -> value

    @property
    def overrides(self):
        return [f"{p}={v}" for p, v in self.columns.items()]

    @property
    def failed(self):
        return self.status.startswith("failed")


@dataclass
class SweepPlan:
    path: Path
    out: Path
    metrics: list  # texts
    runs: list
    cluster: object  # the validated cluster section

    @property
    def invalid(self):
        return [r for r in self.runs if r.problem]


def plan_sweep(path, out=None):
    """Validate the sweep file, expand its grids and validate every run's case.

    Returns a :class:`SweepPlan`; runs whose case fails validation carry the first problem
    in ``problem``. Raises :class:`SweepFileError` for a bad sweep file, including a metric
    whose stage no valid run's case has.
    """
    from demcli.stages.base import load_case  # the stage registry: imported when needed

    node, marks = load_sweep(path)
    path = Path(path)
    out = Path(out) if out else Path(node.out) if node.out else Path("sweeps") / path.stem
    runs = []
    for k, run in enumerate(node.runs):
        grid = _grid(node, k, run)
        case_path = Path(run.case) if Path(run.case).is_absolute() else path.parent / run.case
        points = grid.variants or [None]
        for var in points:
            columns = dict(grid.fixed)
            rid, folder = grid.name, out / grid.name
            if var is not None:
                columns.update((v.path, value) for v, value in zip(grid.varies, var.values))
                rid, folder = f"{grid.name}/{var.slug}", folder / var.slug
            runs.append(SweepRun(rid, run.case, case_path, columns, folder))
    cache = {}
    for r in runs:
        key = (str(r.case_path), tuple(r.overrides))
        if key not in cache:
            try:
                case = load_case(r.case_path, r.overrides)
                cache[key] = ("", tuple(s.name for s in case.stages))
            except ConfigError as exc:
                more = f" (and {len(exc.errors) - 1} more)" if len(exc.errors) > 1 else ""
                cache[key] = (f"invalid case: {exc.errors[0]}{more}", ())
            except DemcliError as exc:
                cache[key] = ("invalid case: " + exc.format_message().splitlines()[0], ())
        r.problem, r.stages = cache[key]
    valid = [r for r in runs if not r.problem]
    if valid:
        issues = []
        for i, text in enumerate(node.metrics):
            stage = parse_metric(text).stage
            if not any(stage in r.stages for r in valid):
                have = sorted({s for r in valid for s in r.stages})
                line = marks.get(("metrics", i)) or marks.get(("metrics",))
                issues.append(ConfigIssue(str(path), line, format_path(("metrics", i)),
                                          f"no run's case has a stage {stage!r} (stages: {', '.join(have)})", text))
        if issues:
            raise SweepFileError(issues)
    return SweepPlan(path, out, list(node.metrics), runs, node.cluster)


def check_sweep(path, out=None, echo=print):
    """``demcli sweep --check``: ``echo`` the run list (id, case, overrides); InputError
    (exit 2) when a run's case fails validation. Returns the :class:`SweepPlan`."""
    plan = plan_sweep(path, out)
    n = len(plan.runs)
    echo(f"sweep {plan.path}: {n} run{'s' if n != 1 else ''} -> {plan.out}")
    for r in plan.runs:
        sets = " ".join(f"--set {shlex.quote(o)}" for o in r.overrides)
        echo(f"  {r.id}: {r.case} {sets}".rstrip() + (f"\n      INVALID: {r.problem}" if r.problem else ""))
    if plan.invalid:
        k = len(plan.invalid)
        raise InputError(f"{k} of {n} run{'s' if n != 1 else ''} fail{'s' if k == 1 else ''} validation (above)")
    return plan


# ---------------------------------------------------------------------------------------
# one run, in a Dask worker

# The child process runs `demcli run`. On Linux it asks for SIGINT when the worker thread
# that started it ends, so that closing the cluster (Ctrl-C) stops its runs as Ctrl-C stops
# `demcli run`, instead of leaving them running with nobody waiting for them.
_CHILD = """\
import os, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)  # a worker may ignore SIGINT; runs must not
if sys.platform.startswith("linux"):
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGINT), 0, 0, 0)  # PR_SET_PDEATHSIG
    except Exception:
        pass
    if str(os.getppid()) != os.environ.get("DEMCLI_SWEEP_PARENT", str(os.getppid())):
        sys.exit("demcli sweep: the worker that started this run is gone")
from demcli.cli import main
main(sys.argv[1:])
"""


def child_command(argv):
    """The command line of a run's child process: ``demcli ARGV`` in this Python, with ``-P``
    so that the current folder does not come first on the import path (run from the folder
    that holds a checkout named ``demcli``, ``import demcli`` would find that folder)."""
    return [sys.executable, "-P", "-c", _CHILD, *argv]


def _error_line(output, returncode):
    """The first line of the run's error: demcli's ``Error: ...`` (with its detail line when
    the first one ends in a colon), else the last line of a traceback, else how it ended."""
    lines = output.splitlines()
    for i in range(len(lines) - 1, -1, -1):
        if lines[i].startswith("Error: "):
            text = lines[i][len("Error: "):].strip()
            if text.endswith(":") and i + 1 < len(lines):
                text += " " + lines[i + 1].strip()
            return text
    if returncode < 0:
        try:
            return f"killed by signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    tail = [ln.strip() for ln in lines if ln.strip()]
    return f"exit code {returncode}" + (f": {tail[-1]}" if tail else "")


def _run_one(job):
    """Run one sweep run (a Dask task): ``demcli run`` in a child process, then its metrics.

    Returns a plain dict and never raises: ``status`` (``ok``, ``reused`` or ``failed``),
    ``message``, ``wall_time``, ``metrics`` (text -> [value, unit]) and ``metric_errors``.
    """
    folder = Path(job["out"])
    argv = ["run", job["case"], "--out", job["out"], "--threads", str(job["threads"])]
    argv += ["--force"] * bool(job["force"]) + ["--resume"] * bool(job["resume"])
    for o in job["overrides"]:
        argv += ["--set", o]
    reply = {"id": job["id"], "status": "failed", "message": "", "wall_time": math.nan, "metrics": {},
             "metric_errors": {}}
    log_path = folder / "sweep.log"
    t0 = time.perf_counter()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ, DEMCLI_SWEEP_PARENT=str(os.getpid()))
        # output to a file, not a pipe: a run outlives a dead worker long enough to checkpoint
        head = f"$ {shlex.join(['demcli', *argv])}\n# worker {platform.node()} pid {os.getpid()}\n"
        with open(log_path, "w", encoding="utf-8") as out:
            out.write(head)
            out.flush()
            code = subprocess.call(child_command(argv), stdout=out, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, env=env)
        reply["wall_time"] = time.perf_counter() - t0
        output = log_path.read_text(encoding="utf-8", errors="replace")[len(head):]
        with open(log_path, "a", encoding="utf-8") as out:
            out.write(f"# exit code {code}, {reply['wall_time']:.2f} s\n")
    except OSError as exc:
        reply["message"] = f"cannot run it: {exc}"
        return reply
    if code != 0:
        reply["message"] = _error_line(output, code)
        return reply
    stages = [m[2] for m in map(_STAGE_LINE.match, output.splitlines()) if m]
    reply["status"] = "reused" if stages and all(s == "skipped" for s in stages) else "ok"
    for text in job["metrics"]:
        try:
            reply["metrics"][text] = list(read_metric(folder, parse_metric(text)))
        except Exception as exc:  # a missing table or column, an unreadable record
            msg = exc.format_message() if isinstance(exc, DemcliError) else f"{type(exc).__name__}: {exc}"
            reply["metric_errors"][text] = (msg.splitlines() or [""])[0]
    return reply


# ---------------------------------------------------------------------------------------
# the cluster

def _dask():
    try:
        from dask import distributed
    except ImportError:
        raise InputError("demcli sweep needs Dask's distributed scheduler, which is not installed: "
                         "pip install 'dask[distributed]'") from None
    return distributed


def _open_client(stack, kind, workers, threads_per_run, options, scheduler, n_runs, log):
    """A Dask client on the chosen cluster; the cluster and client close with ``stack``."""
    distributed = _dask()
    if scheduler:
        log(f"connecting to the Dask scheduler at {scheduler}")
        try:
            client = stack.enter_context(distributed.Client(scheduler, timeout="30s"))
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there: {exc}") from None
        if not client.scheduler_info().get("workers"):
            log("the scheduler has no workers yet; the runs wait until some connect")
        return client
    kwargs = dict(options)
    if kind == "local":
        for key, value in (("n_workers", default_jobs(threads_per_run, n_runs)), ("threads_per_worker", 1),
                           ("processes", True), ("dashboard_address", None), ("silence_logs", logging.ERROR)):
            kwargs.setdefault(key, value)
        if workers:
            kwargs["n_workers"] = workers
        log(f"starting a local Dask cluster: {kwargs['n_workers']} worker process"
            f"{'es' if kwargs['n_workers'] != 1 else ''}, {threads_per_run} kernel thread"
            f"{'s' if threads_per_run != 1 else ''} per run")
        try:
            cluster = stack.enter_context(distributed.LocalCluster(**kwargs))
        except (TypeError, ValueError, RuntimeError) as exc:  # an unknown option fails in the worker: RuntimeError
            hint = f"; check cluster.options {options}" if options else ""
            raise InputError(f"the local Dask cluster did not start: {type(exc).__name__}: {exc}{hint}") from None
    else:
        try:
            import dask
            import dask_jobqueue
        except ImportError:
            raise InputError(f"cluster type {kind} needs dask-jobqueue, which is not installed: "
                             "pip install dask-jobqueue (set-up: docs/sweep.md)") from None
        cls = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[kind]
        submit = {"slurm": "sbatch", "pbs": "qsub"}[kind]
        if shutil.which(submit) is None:  # else every job submission fails and the runs wait forever
            raise InputError(f"cluster type {kind}: {submit} is not on PATH; run the sweep on a {kind.upper()} "
                             "login node (or use --scheduler, or the local cluster)")
        # one run per worker thread, unless the user's jobqueue config says otherwise
        for key, value in (("cores", 1), ("processes", 1)):
            if key not in kwargs and dask.config.get(f"jobqueue.{kind}.{key}", None) is None:
                kwargs[key] = value
        if "memory" not in kwargs and dask.config.get(f"jobqueue.{kind}.memory", None) is None:
            raise InputError(f"cluster type {kind}: give the memory per job, in cluster.options (memory: 4GB) "
                             f"or in the dask-jobqueue configuration (jobqueue.{kind}.memory)")
        if kind == "slurm" and "job_cpu" not in kwargs and dask.config.get("jobqueue.slurm.job-cpu", None) is None:
            kwargs["job_cpu"] = threads_per_run * int(kwargs.get("cores", 1))
        try:
            cluster = cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise InputError(f"cluster.options for {kind} ({cls.__name__}): {exc}") from None
        stack.callback(_close_jobs, cluster, log)
        n = workers or min(n_runs, 20)
        log(f"submitting {kind} jobs for {n} Dask worker{'s' if n != 1 else ''} ({cls.__name__}); "
            "the runs start as the jobs do")
        cluster.scale(n)
        # a failed submission is only logged by Dask (the message is above): stop rather than wait forever
        deadline = time.monotonic() + 60
        while not any(getattr(job, "job_id", None) for job in list(cluster.workers.values())):
            if time.monotonic() > deadline:
                raise InputError(f"cluster type {kind}: no job was submitted within 60 s ({submit} failed; "
                                 "see the messages above)")
            time.sleep(0.5)
        log(f"job {next(j.job_id for j in cluster.workers.values() if getattr(j, 'job_id', None))} submitted"
            + (f" (and {n - 1} more asked for)" if n > 1 else ""))
    return stack.enter_context(distributed.Client(cluster))


def _close_jobs(cluster, log):
    """Close a dask-jobqueue cluster (cancelling its jobs); a failure to close is reported, not raised,
    so that it never hides the sweep's own outcome."""
    try:
        cluster.close()
    except Exception as exc:  # e.g. jobs whose submission failed cannot be closed cleanly
        log(f"warning: closing the {type(cluster).__name__} failed ({type(exc).__name__}: {exc}); "
            "check for jobs left in the queue")


# ---------------------------------------------------------------------------------------
# the sweep

@dataclass
class SweepResult:
    plan: SweepPlan
    units: dict  # metric text -> unit
    files: list = field(default_factory=list)
    table: str = ""
    warnings: list = field(default_factory=list)

    @property
    def runs(self):
        return self.plan.runs

    @property
    def failed(self):
        return [r for r in self.plan.runs if r.failed]


def run_sweep(path, out=None, workers=None, scheduler=None, cluster=None, threads_per_run=None, force=False,
              resume=False, log=None):
    """Run a sweep; returns a :class:`SweepResult` (``sweep.csv`` and ``status.csv`` written under the output folder).

    Args:
        path: the sweep file (YAML).
        out: output folder (default: the file's ``out``, else ``sweeps/<file stem>``).
        workers: Dask workers to start (local: default the free cores // threads per run;
            slurm/pbs: default one per run, at most 20). Ignored with ``scheduler``.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``) to use instead.
        cluster: ``local``, ``slurm`` or ``pbs`` (default: the file's ``cluster.type``).
        threads_per_run: kernel threads of each run (default: the file's, else 1).
        force: re-run stages that are up to date.
        resume: continue stages interrupted in an earlier sweep from their checkpoints.
        log: ``log(text)`` for progress lines (None: silent).

    Raises SweepFileError / InputError (exit 2) for a bad sweep file, a missing Dask or
    dask-jobqueue, or a scheduler that cannot be reached, all before any run starts.
    Failed runs are reported in the result (``failed``), never raised.
    """
    log = log or (lambda text: None)
    plan = plan_sweep(path, out)
    kind = cluster or plan.cluster.type
    threads = int(threads_per_run or plan.cluster.threads_per_run)
    workers = workers or plan.cluster.workers
    todo = [r for r in plan.runs if not r.problem]
    n = len(plan.runs)
    log(f"sweep {plan.path}: {n} run{'s' if n != 1 else ''} -> {plan.out}")
    for r in plan.invalid:
        r.status = "failed: " + r.problem
        log(f"{r.id}: FAILED before starting: {r.problem}")
    units, warnings = {}, {}
    started = [not todo]  # reports are written once runs start (a bad --scheduler keeps the old ones)
    done = [len(plan.invalid)]

    def on_done(run, reply):
        done[0] += 1
        run.wall_time = reply.get("wall_time", math.nan)
        if reply["status"] == "failed":
            run.status = "failed: " + (reply["message"] or "unknown error")
        else:
            run.status = reply["status"]
            for text, (value, unit) in reply["metrics"].items():
                run.metrics[text] = value
                units.setdefault(text, unit)
            for text, msg in reply["metric_errors"].items():
                warnings.setdefault(text, f"metric {text} not read in {run.id}: {msg}")
        log(f"[{done[0]}/{n}] {run.id}: {run.status}, {run.wall_time:.2f} s")

    try:
        if todo:
            with contextlib.ExitStack() as stack:
                client = _open_client(stack, kind, workers, threads, dict(plan.cluster.options), scheduler,
                                      len(todo), log)
                started[0] = True
                _submit(client, todo, plan, threads, force, resume, on_done)
    except KeyboardInterrupt:
        for r in plan.runs:
            if r.status == "not run":
                r.status = "not run (sweep interrupted)"
        raise
    finally:
        result = SweepResult(plan, units, warnings=list(warnings.values()))
        result.table = status_table(result)
        if started[0]:
            result.files = _write_reports(result)
    return result


def _submit(client, runs, plan, threads, force, resume, on_done):
    """Submit one Dask task per run and report each as it finishes (a lost worker fails its run only)."""
    distributed = _dask()
    token = uuid.uuid4().hex[:8]
    futures = {}
    for k, r in enumerate(runs):
        job = {"id": r.id, "case": str(r.case_path.resolve()), "out": str(r.folder.resolve()),
               "overrides": r.overrides, "threads": threads, "force": bool(force), "resume": bool(resume),
               "metrics": [m for m in plan.metrics if parse_metric(m).stage in r.stages]}
        futures[client.submit(_run_one, job, key=f"demcli-run-{k}-{token}", pure=False)] = r
    try:
        for fut in distributed.as_completed(list(futures)):
            run = futures[fut]
            try:
                reply = fut.result()
            except Exception as exc:  # the worker died or was lost (KilledWorker, CancelledError, ...)
                first = (str(exc).strip().splitlines() or [""])[0]
                reply = {"status": "failed", "message": f"the Dask task failed: {type(exc).__name__}: {first}"}
            on_done(run, reply)
    except BaseException:
        client.cancel(list(futures))
        raise


# ---------------------------------------------------------------------------------------
# reports

def _metric_header(text, units):
    return _header(parse_metric(text).text, units.get(text, ""))


def _write_reports(result):
    """``sweep.csv`` (overrides, metrics, status, wall time per run) and ``status.csv``."""
    plan = result.plan
    plan.out.mkdir(parents=True, exist_ok=True)
    paths = list(dict.fromkeys(p for r in plan.runs for p in r.columns))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["run", "case", *paths, *(_metric_header(m, result.units) for m in plan.metrics), "status",
                "wall_time[s]"])
    for r in plan.runs:
        w.writerow([r.id, r.case, *(r.columns.get(p, "") for p in paths),
                    *(_num(r.metrics.get(m), "r") for m in plan.metrics), r.status, _num(r.wall_time, "r")])
    atomic_write_text(plan.out / "sweep.csv", buf.getvalue())
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["run", "case", "status", "wall_time[s]", "folder"])
    for r in plan.runs:
        w.writerow([r.id, r.case, r.status, _num(r.wall_time, "r"), str(r.folder)])
    atomic_write_text(plan.out / "status.csv", buf.getvalue())
    return [plan.out / "sweep.csv", plan.out / "status.csv"]


def status_table(result):
    """The status of every run as a Markdown table: run, status, wall time."""
    rows = [(r.id, r.status.replace("|", "\\|"), _num(r.wall_time, ".2f")) for r in result.runs]
    lines = ["| run | status | wall time [s] |", "|:---|:---|---:|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines) + "\n"
