"""``demcli study``: what accuracy costs in time.

A study runs one case several times with settings varied (``--vary path=v1,v2,...``;
several ``--vary`` make a grid, their cartesian product, and ``--vary +path=w1,w2,...`` varies
a path together with the one before it, paired by position), reads one number from each
run's records (``--metric STAGE.TABLE.COLUMN[@last|@first|@max|@min|@mean]``) and reports,
per variant, the varied values, the metric, its error against the finest variant and the
wall time, as ``study.csv``, ``study.md`` and an error-versus-time plot ``study.png``::

    studies/<case>/                 (--out)
      <variant>/                    one run folder per variant, e.g. dt_factor=0.1/
      study.csv, study.md, study.png
      study.json                    manifest: each variant's overrides and stage wall times

A variant is the case with ``--set``-style overrides, so values take units (``"2 mm"``)
and every variant is validated, with the case's own rules, before any runs. Variants are
independent runs in their own folders: run in parallel (``--jobs``) they give the same
numbers as run one after the other, and a variant whose stages are up to date is not run
again (its wall time comes from the manifest).

The wall time of a variant is the sum of its stages' wall times. numba's first call in a
process loads the compiled kernels (about a second); unless ``cold`` is asked for, a
process's first run is therefore repeated and the second, warm time is reported, so that
every variant is timed the same way.
"""

from __future__ import annotations

import itertools
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from demcli import study_stats
from demcli.errors import ConfigError, DemcliError, InputError, StageError
from demcli.state.atomic import atomic_path, atomic_write_text

__all__ = ["Vary", "Variant", "Metric", "parse_vary", "make_variants", "parse_metric", "check_metric_stage",
           "reduce_column", "read_metric", "pick_reference", "error_table", "validate_variants", "write_csv",
           "parse_realisations", "markdown_table", "write_plot", "run_study", "StudyResult"]

REDUCERS = ("last", "first", "max", "min", "mean")
MANIFEST = "study.json"
_SLUG_CHARS = re.compile(r"[^A-Za-z0-9._+\-]")


# ---------------------------------------------------------------------------------------
# what is varied

@dataclass(frozen=True)
class Vary:
    """One ``--vary``: a case path and the values (YAML text, as ``--set`` takes them).

    ``along``: varied together with the ``--vary`` before it (written ``+path=...``): the
    values pair by position instead of making a grid. ``group``: the index of the grid axis
    the path belongs to (set by :func:`make_variants`).
    """

    path: str
    values: tuple
    label: str = ""  # short name in tables and folder names (the path's last segments)
    along: bool = False
    group: int = 0
    realisation: bool = False  # the runs along this path are realisations of one setting (--realisations)


@dataclass(frozen=True)
class Variant:
    """One run of a study: the value taken from each Vary, as overrides and a folder name."""

    slug: str
    values: tuple  # the value text per Vary, in --vary order

    def overrides(self, varies):
        return [f"{v.path}={value}" for v, value in zip(varies, self.values)]


def split_values(text):
    """Split ``v1,v2,...`` at the commas outside brackets and quotes (``[1, 2],[3, 4]``)."""
    parts, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[{(":
            depth += 1
        elif ch in "]})":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    parts.append("".join(cur).strip())
    return parts


def parse_vary(text):
    """A :class:`Vary` from ``path=v1,v2,...``, or ``+path=v1,v2,...`` for a path varied
    along with the previous one; InputError naming the rule it breaks."""
    path, sep, values = text.partition("=")
    path = path.strip()
    where = f"--vary {text}"
    along = path.startswith("+")
    path = path[1:].strip() if along else path
    if not sep or not path:
        raise InputError(f"{where}: write PATH=V1,V2,..., e.g. stages.settle.time.dt_factor=0.4,0.2,0.1")
    if any(not seg.strip() for seg in path.split(".")):
        raise InputError(f"{where}: empty segment in path {path!r}")
    vals = split_values(values)
    if any(not v for v in vals):
        raise InputError(f"{where}: empty value (two commas in a row, or a trailing comma?)")
    seen = set()
    for v in vals:
        if v in seen:
            raise InputError(f"{where}: value {v!r} is given twice")
        seen.add(v)
    return Vary(path, tuple(vals), along=along)


def _labels(paths):
    """Shortest unique tail of each path: ``dt_factor``, or ``settle.time.dt_factor`` on a clash."""
    segs = [p.split(".") for p in paths]
    depth = [1] * len(paths)
    while True:
        labels = [".".join(s[-d:]) for s, d in zip(segs, depth)]
        clash = [i for i, lab in enumerate(labels) if labels.count(lab) > 1 and depth[i] < len(segs[i])]
        if not clash:
            return labels
        for i in clash:
            depth[i] += 1


def _slug_value(value):
    return _SLUG_CHARS.sub("_", value.replace(" ", "")) or "_"


def make_variants(varies):
    """``(varies with labels and groups, variants)``: the grid of every combination, first
    --vary slowest; a ``+path`` --vary (``along``) joins the axis of the one before it, its
    values paired with that one's by position. A variant's folder name holds the first path
    of each axis (its values are distinct, so they name the variant)."""
    if not varies:
        raise InputError("a study needs at least one --vary PATH=V1,V2,...")
    paths = [v.path for v in varies]
    for p in paths:
        if paths.count(p) > 1:
            raise InputError(f"--vary {p}: the path is varied twice; give all its values in one --vary")
    if varies[0].along:
        raise InputError(f"--vary +{varies[0].path}: a leading + joins the --vary before it, and there is none")
    groups = [g - 1 for g in itertools.accumulate(0 if v.along else 1 for v in varies)]  # axis of each path
    for v, g in zip(varies, groups):
        head = varies[groups.index(g)]
        if v.along and len(v.values) != len(head.values):
            raise InputError(f"--vary +{v.path}: {len(v.values)} values to pair with the {len(head.values)} of "
                             f"--vary {head.path}; a + path needs one value per value of the path it joins")
    varies = [Vary(v.path, v.values, lab, v.along, g, v.realisation)
              for v, lab, g in zip(varies, _labels(paths), groups)]
    for v in varies:
        slugs = {}
        for value in v.values:
            s = _slug_value(value)
            if s in slugs:
                raise InputError(f"--vary {v.path}: values {slugs[s]!r} and {value!r} name the same folder "
                                 f"({v.label}={s}); write them alike or drop one")
            slugs[s] = value
    axes = [[k for k, g in enumerate(groups) if g == a] for a in range(groups[-1] + 1)]
    variants = []
    for picks in itertools.product(*(range(len(varies[ax[0]].values)) for ax in axes)):
        combo = [None] * len(varies)
        for ax, i in zip(axes, picks):
            for k in ax:
                combo[k] = varies[k].values[i]
        slug = ",".join(f"{varies[ax[0]].label}={_slug_value(combo[ax[0]])}" for ax in axes)
        variants.append(Variant(slug, tuple(combo)))
    return varies, variants


def validate_variants(case, varies, variants, overrides=()):
    """Load every variant with the case's rules; InputError listing each failing variant.

    The fixed ``overrides`` are checked alone first, so their problems are named once.
    Returns the validated case of the first variant (for its name and stages).
    """
    from demcli.stages.base import load_case

    base = load_case(case, list(overrides))
    problems = []
    for var in variants:
        try:
            load_case(case, list(overrides) + var.overrides(varies))
        except ConfigError as exc:
            problems.append(f"variant {var.slug}:\n    " + "\n    ".join(str(e) for e in exc.errors))
    if problems:
        n = len(variants)
        head = f"{len(problems)} of {n} variant{'s' if n > 1 else ''} fail{'s' if len(problems) == 1 else ''}"
        raise InputError(f"invalid study ({head} validation; nothing was run):\n  " + "\n  ".join(problems))
    return base


def pick_reference(varies, variants, spec="last"):
    """Index of the reference (finest) variant: ``last`` (each --vary's last value),
    ``first``, or a variant's name (its folder name, e.g. ``dt_factor=0.1``; with realisations
    also the setting's name, the folder name without its realisation part)."""
    spec = (spec or "last").strip()
    if spec in ("last", "first"):
        want = tuple(v.values[-1 if spec == "last" else 0] for v in varies)
        return next(i for i, var in enumerate(variants) if var.values == want)
    real = varies[-1].realisation and len(varies) > 1  # a setting's name: the slug without its realisation

    def setting(slug):
        return slug.rpartition(",")[0] if real else slug

    for i, var in enumerate(variants):
        if spec.replace(" ", "") in (var.slug.replace(" ", ""), setting(var.slug).replace(" ", "")):
            return i
    names = [v.slug for v in variants]
    shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
    raise InputError(f"--reference {spec}: no such variant; use last, first or one of: {shown}")


# ---------------------------------------------------------------------------------------
# the metric

@dataclass(frozen=True)
class Metric:
    """``STAGE.TABLE.COLUMN@REDUCER``: a column of ``records/<stage>_<table>.csv``, reduced."""

    stage: str
    table: str
    column: str
    reducer: str = "last"

    @property
    def text(self):
        return f"{self.stage}.{self.table}.{self.column}@{self.reducer}"

    @property
    def record(self):
        return f"{self.stage}_{self.table}"


def parse_metric(text):
    """A :class:`Metric` from ``stage.table.column[@reducer]`` (the column may hold dots,
    as wall columns do: ``impact.walls.floor.force@max``)."""
    body, at, reducer = text.strip().rpartition("@")
    if not at:
        body, reducer = reducer, "last"
    parts = body.split(".", 2)
    if len(parts) != 3 or not all(p.strip() for p in parts):
        raise InputError(f"--metric {text}: write STAGE.TABLE.COLUMN[@REDUCER], "
                         "e.g. settle.dem.kinetic@last (records/settle_dem.csv, column kinetic)")
    if reducer not in REDUCERS:
        raise InputError(f"--metric {text}: unknown reducer @{reducer}; use one of "
                         + ", ".join("@" + r for r in REDUCERS))
    return Metric(*(p.strip() for p in parts), reducer)


def check_metric_stage(metric, case_node):
    """InputError when the metric names a stage the case does not have."""
    import difflib

    names = [s.name for s in case_node.stages]
    if metric.stage not in names:
        close = difflib.get_close_matches(metric.stage, names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else f"; stages are {', '.join(names)}"
        raise InputError(f"--metric {metric.text}: the case has no stage {metric.stage!r}{hint}")


def reduce_column(values, reducer):
    """One number from a record column: its last, first, max, min or mean value."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        raise InputError("the record has no rows")
    if reducer == "last":
        return float(values[-1])
    if reducer == "first":
        return float(values[0])
    return float({"max": np.max, "min": np.min, "mean": np.mean}[reducer](values))


def read_metric(run_dir, metric):
    """``(value, unit)`` of ``metric`` in a run folder's records; InputError naming what
    is missing (the record file, with the ones there are, or the column, with the columns)."""
    from demcli.compare import read_record

    folder = Path(run_dir) / "records"
    path = folder / f"{metric.record}.csv"
    if not path.exists():
        have = sorted(p.stem for p in folder.glob(f"{metric.stage}_*.csv"))
        have = ", ".join(h[len(metric.stage) + 1:] for h in have) or "none"
        raise InputError(f"--metric {metric.text}: stage {metric.stage} wrote no record table "
                         f"{metric.table!r} ({path}); its tables: {have}")
    data, units = read_record(path)
    if metric.column not in data:
        raise InputError(f"--metric {metric.text}: {path.name} has no column {metric.column!r}; "
                         f"columns: {', '.join(data)}")
    try:
        value = reduce_column(data[metric.column], metric.reducer)
    except InputError as exc:
        raise InputError(f"--metric {metric.text}: {path}: {exc}") from None
    return value, units[metric.column]


def error_table(values, ref):
    """``[(error, relative error)]`` of each value against ``values[ref]``.

    error = value - reference (signed); relative error = |error| / |reference| (NaN when
    the reference is zero or either value is missing). The reference itself gets (0, 0).
    """
    r = values[ref]
    out = []
    for k, v in enumerate(values):
        if k == ref and math.isfinite(r):
            out.append((0.0, 0.0))
            continue
        err = v - r
        rel = abs(err) / abs(r) if (math.isfinite(err) and r != 0) else math.nan
        out.append((err, rel))
    return out


# ---------------------------------------------------------------------------------------
# running

_WARM = False  # this process has run a stage: numba's kernels are loaded


def _run_variant(job):
    """Run one variant (in this process or a spawned worker); a plain dict back.

    DemcliErrors come back as ``status`` and ``message`` (their classes do not pickle
    their arguments faithfully); anything else is a bug and propagates.
    """
    global _WARM
    from demcli.interrupts import restore, stop_as_interrupt
    from demcli.pipeline import run_case

    def once(force):
        return run_case(job["case"], out=job["out"], overrides=job["overrides"], threads=job["threads"],
                        quiet=True, force=force)

    # a worker stops its variant at SIGTERM as at Ctrl-C (an idle one just exits)
    previous = stop_as_interrupt()
    try:
        results = once(job["force"])
        ran = any(not r.skipped for r in results)
        repeated = False
        if ran and not _WARM and not job["cold"]:
            _WARM = True
            results = once(True)  # timed again, now with the kernels loaded
            repeated = True
        _WARM = _WARM or ran
    except StageError as exc:
        # Ctrl-C inside a stage becomes a StageError (with a checkpoint): it stops the study
        status = "interrupted" if isinstance(exc.__context__, KeyboardInterrupt) else "failed"
        return {"slug": job["slug"], "status": status, "message": exc.format_message(), "stages": []}
    except DemcliError as exc:
        return {"slug": job["slug"], "status": "error", "exit_code": exc.exit_code,
                "message": exc.format_message(), "stages": []}
    finally:
        restore(previous)
    return {"slug": job["slug"], "status": "ok", "message": "", "repeated": repeated,
            "stages": [(r.name, str(r.path), bool(r.skipped), float(r.wall_time)) for r in results]}


def default_jobs(threads_per_job, n_variants):
    """Free cores // threads per job, at least 1, at most the number of variants."""
    from demcli.jit import free_cores

    return max(1, min(n_variants, free_cores() // max(1, threads_per_job)))


def _execute(jobs_list, jobs, on_done):
    """Run the jobs, ``jobs`` at a time (spawned workers when more than one)."""
    if jobs <= 1:
        for job in jobs_list:
            on_done(job, _run_variant(job))
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ex = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = {ex.submit(_run_variant, job): job for job in jobs_list}
        for fut in as_completed(futures):
            on_done(futures[fut], fut.result())
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt):
            # Ctrl-C reaches the whole process group, a SIGTERM (kill, a job's limit) only this
            # process: pass it on, so that the running variants stop now instead of running on
            for proc in multiprocessing.active_children():
                proc.terminate()
        ex.shutdown(wait=True, cancel_futures=True)
        raise
    ex.shutdown(wait=True)


_DONE_LINE = re.compile(r"\[(?P<stage>[^\]]+)\] done in (?P<t>[0-9.eE+-]+) s")


def _logged_time(log_path, stage):
    """The stage's last ``done in X s`` in a run's log.txt (NaN when there is none)."""
    try:
        text = Path(log_path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return math.nan
    times = [float(m["t"]) for m in _DONE_LINE.finditer(text) if m["stage"] == stage]
    return times[-1] if times else math.nan


def _stage_times(reply, run_dir, stored):
    """``(total wall time, {stage: entry})``; a skipped stage takes the time stored when it
    ran: from the manifest when its state's hashes match, else from the run's log.txt."""
    from demcli.state import read_meta

    entries, total = {}, 0.0
    for name, path, skipped, wall in reply["stages"]:
        meta = read_meta(path)
        key = {"config_hash": meta.get("config_hash", ""), "input_hash": meta.get("input_hash", "")}
        if skipped:
            old = stored.get(name) or {}
            if all(old.get(k) == v for k, v in key.items()) and "wall_time" in old:
                wall = float(old["wall_time"])
            else:
                wall = _logged_time(Path(run_dir) / "log.txt", name)
        entries[name] = {"wall_time": wall, **key}
        total += wall
    return total, entries


@dataclass
class Row:
    """One variant's line in the report."""

    variant: Variant
    metric: float = math.nan
    error: float = math.nan
    rel_error: float = math.nan
    wall_time: float = math.nan
    status: str = ""


@dataclass
class StudyResult:
    case: str
    metric: Metric
    unit: str
    varies: list
    rows: list
    reference: int
    out: Path
    files: list = field(default_factory=list)
    markdown: str = ""
    settings: list = field(default_factory=list)  # with realisations: one study_stats.Setting per setting
    setting_reference: int = 0

    @property
    def failed(self):
        return [r for r in self.rows if r.status.startswith("failed")]


def run_study(case, varies, metric, out=None, jobs=None, threads_per_job=1, reference="last", overrides=(),
              force=False, cold=False, log=None, realisations=None):
    """Run a study; returns a :class:`StudyResult` (reports written under ``out``).

    Args:
        case: the YAML case.
        varies: ``--vary`` texts (``path=v1,v2``) or :class:`Vary` objects.
        metric: ``stage.table.column[@reducer]`` text or a :class:`Metric`.
        out: the study folder (default ``studies/<case name>``).
        jobs: variants run at once (default: free cores // threads_per_job).
        threads_per_job: numba threads of each variant's run.
        reference: ``last``, ``first`` or a variant's name: the finest variant.
        overrides: ``--set`` texts applied to every variant.
        force: re-run variants whose stages are up to date.
        cold: report each run's time as it comes, first-call kernel loading included.
        log: ``log(text)`` for one line per finished variant (None: silent).
        realisations: ``path=v1,v2,...`` (e.g. ``seed=1,2,3``): every setting is run once per value and
            reported as mean and spread over them (:mod:`demcli.study_stats`); errors are then taken
            against the reference setting's mean.

    Raises InputError (exit 2) for a bad --vary, --metric or --reference, or any variant
    that fails validation, all before anything runs; StageError (exit 1) when the
    reference variant fails. Other failing variants are reported in the table.
    """
    log = log or (lambda text: None)
    varies = [v if isinstance(v, Vary) else parse_vary(v) for v in varies]
    if realisations is not None:
        varies.append(parse_realisations(realisations))
    metric = metric if isinstance(metric, Metric) else parse_metric(metric)
    varies, variants = make_variants(varies)
    fixed = list(overrides)
    for text in fixed:
        path = text.partition("=")[0].strip()
        if any(v.path == path for v in varies):
            raise InputError(f"--set {text}: {path} is also varied by --vary; drop one of them")
    ref = pick_reference(varies, variants, reference)
    base = validate_variants(case, varies, variants, fixed)
    check_metric_stage(metric, base)
    name = base.name or Path(case).stem
    out = Path(out) if out else Path("studies") / name
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    manifest = _read_manifest(manifest_path)
    stored = manifest.setdefault("variants", {})
    jobs = default_jobs(threads_per_job, len(variants)) if jobs is None else max(1, min(int(jobs), len(variants)))
    log(f"study of {case}: {len(variants)} variant{'s' if len(variants) != 1 else ''}, {jobs} at a time, "
        f"{threads_per_job} thread{'s' if threads_per_job != 1 else ''} each -> {out}")

    rows = {v.slug: Row(v) for v in variants}
    unit = [""]
    done = [0]
    job_list = [{"slug": v.slug, "case": str(case), "out": str(out / v.slug), "overrides": fixed + v.overrides(varies),
                 "threads": int(threads_per_job), "force": bool(force), "cold": bool(cold)} for v in variants]

    def on_done(job, reply):
        row = rows[reply["slug"]]
        done[0] += 1
        if reply["status"] == "error":
            cls = InputError if reply["exit_code"] == 2 else DemcliError
            raise cls(f"variant {row.variant.slug}: {reply['message']}")
        if reply["status"] == "interrupted":
            raise StageError(f"study interrupted in variant {row.variant.slug}: {reply['message']}")
        if reply["status"] == "failed":
            row.status = "failed: " + reply["message"].splitlines()[0]
            log(f"[{done[0]}/{len(variants)}] {row.variant.slug}: FAILED: {reply['message'].splitlines()[0]}")
            return
        entry = stored.get(row.variant.slug, {})
        row.wall_time, stages = _stage_times(reply, job["out"], entry.get("stages", {}))
        stored[row.variant.slug] = {"overrides": job["overrides"], "stages": stages}
        row.metric, unit[0] = read_metric(job["out"], metric)
        skipped = [s[2] for s in reply["stages"]]
        row.status = "reused" if all(skipped) else ("partly reused" if any(skipped) else "ran")
        note = " (up to date)" if all(skipped) else (" (timed on a second, warm run)" if reply.get("repeated") else "")
        log(f"[{done[0]}/{len(variants)}] {row.variant.slug}: {metric.column}@{metric.reducer} = "
            f"{row.metric:.6g}, {row.wall_time:.2f} s{note}")

    try:
        _execute(job_list, jobs, on_done)
    except KeyboardInterrupt:
        raise StageError("study interrupted; the same command again reuses the variants that finished "
                         "and runs the others") from None
    finally:
        manifest.update({"case": str(case), "metric": metric.text, "set": fixed,
                         "vary": {v.path: list(v.values) for v in varies}})
        atomic_write_text(manifest_path, json.dumps(manifest, indent=1, sort_keys=True) + "\n")

    ordered = [rows[v.slug] for v in variants]
    result = StudyResult(str(case), metric, unit[0], varies, ordered, ref, out)
    values = [r.metric for r in ordered]
    if any(v.realisation for v in varies):
        result.settings, result.setting_reference = study_stats.aggregate(varies, ordered, ref)
        errors = error_table(values + [result.settings[result.setting_reference].mean], len(values))[:-1]
    else:
        errors = error_table(values, ref)
    for row, (err, rel) in zip(ordered, errors):
        row.error, row.rel_error = err, rel
    result.markdown = markdown_table(result)
    write_csv(out / "study.csv", result)
    result.files = [out / "study.csv", out / "study.md"]
    if write_plot(out / "study.png", result):
        result.files.append(out / "study.png")
    if result.settings:
        result.files += _write_settings(result)
    atomic_write_text(out / "study.md", result.markdown)
    if ordered[ref].status.startswith("failed"):
        raise StageError(f"the reference variant {ordered[ref].variant.slug} failed, so there are no errors to "
                         f"report: {ordered[ref].status[len('failed: '):]}\n  table: {out / 'study.md'}")
    return result


def parse_realisations(text):
    """The realisation axis of ``--realisations path=v1,v2,...``: a :class:`Vary` flagged
    ``realisation``; InputError unless it has two values or more and no leading +."""
    vary = parse_vary(text)
    if vary.along:
        raise InputError(f"--realisations {text}: the realisations are their own axis; drop the +")
    if len(vary.values) < 2:
        raise InputError(f"--realisations {text}: give two values or more (e.g. seed=1,2,3): one run shows "
                         "no scatter")
    return Vary(vary.path, vary.values, realisation=True)


def _write_settings(result):
    """settings.csv and settings.png of a study with realisations; the settings table joins the Markdown."""
    name = f"{result.metric.column}@{result.metric.reducer}"
    args = (result.varies, result.settings, result.setting_reference, name, result.unit)
    files = [study_stats.write_settings_csv(result.out / "settings.csv", *args)]
    result.markdown += "\n" + study_stats.settings_markdown(*args)
    if study_stats.write_settings_plot(result.out / "settings.png", result.case, result.varies, result.settings,
                                       name, result.unit):
        files.append(result.out / "settings.png")
    return files


def _read_manifest(path):
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


# ---------------------------------------------------------------------------------------
# reports

def _num(x, fmt):
    """``x`` formatted with ``fmt`` (``"r"``: repr, full precision); empty when missing."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    return repr(float(x)) if fmt == "r" else format(x, fmt)


def _header(name, unit):
    return f"{name}[{unit}]" if unit else name


def write_csv(path, result):
    """``study.csv``: variant, the varied values, metric, error, rel_error, wall_time, status
    (full precision; headers ``name[unit]`` as the record CSVs)."""
    import csv
    import io

    m = f"{result.metric.column}@{result.metric.reducer}"
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["variant", *(v.label for v in result.varies), _header(m, result.unit),
                _header("error", result.unit), "rel_error", "wall_time[s]", "status"])
    for k, row in enumerate(result.rows):
        w.writerow([row.variant.slug, *row.variant.values, *(_num(x, "r") for x in (row.metric, row.error,
                    row.rel_error, row.wall_time)), row.status + (" (reference)" if k == result.reference and not result.settings else "")])
    atomic_write_text(path, buf.getvalue())
    return Path(path)


def markdown_table(result):
    """The report as Markdown: a line on what was measured, then one row per variant."""
    m = result.metric
    unit = f" [{result.unit}]" if result.unit else ""
    ref = result.rows[result.reference].variant
    against = (f"the mean of the reference setting's realisations (`{ref.slug}` and its other "
               f"{next(v.label for v in result.varies if v.realisation)})") if result.settings else \
        f"the reference `{ref.slug}`"
    lines = [f"Study of `{result.case}`: `{m.text}` (records/{m.record}.csv){unit}; error against {against}.", ""]
    show_status = any(r.status != "ran" for r in result.rows)
    head = [*(v.label for v in result.varies), f"{m.column}@{m.reducer}{unit}", f"error{unit}", "rel. error",
            "wall time [s]"] + (["status"] if show_status else [])
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---:|" * (len(head) - show_status) + ":---|" * show_status)
    for k, row in enumerate(result.rows):
        values = list(row.variant.values)
        if k == result.reference and not result.settings:  # with realisations: the setting's mean is
            values[-1] += " (reference)"
        cells = [*values, _num(row.metric, ".6g"), _num(row.error, ".3g"), _num(row.rel_error, ".2e"),
                 _num(row.wall_time, ".2f")] + ([row.status] if show_status else [])
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_plot(path_png, result):
    """Relative error against wall time, log-log, each point labelled with its value of the
    first --vary; one line per combination of the other --vary values. Returns False when
    matplotlib is not installed."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return False
    fig = Figure(figsize=(6.4, 4.4), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    series = {}
    for k, row in enumerate(result.rows):
        if k == result.reference:
            continue
        key = ", ".join(f"{v.label}={val}" for v, val in zip(result.varies, row.variant.values) if v.group > 0)
        series.setdefault(key, []).append(row)
    plotted = 0
    for key, rows in series.items():
        pts = sorted((r.wall_time, r.rel_error, r.variant.values[0]) for r in rows
                     if math.isfinite(r.wall_time) and r.wall_time > 0 and math.isfinite(r.rel_error)
                     and r.rel_error > 0)
        if not pts:
            continue
        ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=key or None)
        for t, e, label in pts:
            ax.annotate(label, (t, e), textcoords="offset points", xytext=(4, 4), fontsize=8)
        plotted += len(pts)
    if plotted:
        ax.set_xscale("log")
        ax.set_yscale("log")
    else:
        ax.text(0.5, 0.5, "no nonzero errors to plot", transform=ax.transAxes, ha="center")
    ref = result.rows[result.reference].variant.slug
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel(f"relative error of {result.metric.column}@{result.metric.reducer}")
    ax.set_title(f"{Path(result.case).stem}: error against {ref}\n(points: {result.varies[0].label})",
                 fontsize=10)
    if len(series) > 1:
        ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_path(path_png) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    return True
