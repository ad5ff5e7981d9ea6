"""Command line: a thin click layer over :mod:`demcli.pipeline` and :mod:`demcli.state`."""

import sys

import click

from demcli import __version__

SET_HELP = ("Override a case value (the value is read as YAML). PATH is dotted keys; a list item goes by its "
            "index or its name, with or without brackets: stages.settle.walls[1].max or stages.settle.walls.1.max, "
            "and stages.settle.walls.lid.max or stages.settle.walls[lid].max for the wall named lid. "
            "E.g. --set stages.settle.time.duration=0.1s")
# demcli.geometry.projection.METHODS, spelt out so that starting the command line loads no scipy
SIEVE_METHODS = ("projection", "volume_sphere", "volume_cube", "inertia_square")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="demcli")
def cli():
    """DEM batch simulator for asphalt mixtures and railway ballast."""


@cli.command()
@click.argument("case", type=click.Path(dir_okay=False))
@click.option("--from", "from_stage", metavar="STAGE", help="Re-run from this stage on.")
@click.option("--only", metavar="STAGE", help="Run only this stage (its input must exist).")
@click.option("--force", is_flag=True, help="Re-run stages even when up to date.")
@click.option("--set", "overrides", multiple=True, metavar="PATH=VALUE", help=SET_HELP)
@click.option("--out", type=click.Path(file_okay=False), help="Run folder (default runs/<case name>).")
@click.option("--threads", type=click.IntRange(min=1), help="Threads for the kernels (default: the cores not busy with other work).")
@click.option("--quiet", is_flag=True, help="No progress or log lines.")
@click.option("--resume", is_flag=True, help="Continue interrupted stages from their checkpoints.")
def run(case, from_stage, only, force, overrides, out, threads, quiet, resume):
    """Run the stages of CASE (a YAML file)."""
    from demcli.interrupts import stop_as_interrupt
    from demcli.pipeline import run_case

    stop_as_interrupt()  # SIGTERM as Ctrl-C: the running stage writes its checkpoint for --resume
    results = run_case(case, out=out, from_stage=from_stage, only=only, force=force, overrides=overrides,
                       threads=threads, quiet=quiet, resume=resume)
    if not quiet:
        for r in results:
            click.echo(f"{r.name:>16}  {'skipped' if r.skipped else f'{r.wall_time:8.2f} s'}  {r.path}")


@cli.command()
@click.argument("case", type=click.Path(dir_okay=False))
@click.option("--set", "overrides", multiple=True, metavar="PATH=VALUE", help=SET_HELP)
def check(case, overrides):
    """Validate CASE and print its plan (compiles nothing)."""
    from demcli.check import describe_case

    click.echo(describe_case(case, overrides))


@cli.command()
@click.argument("state", type=click.Path(dir_okay=False))
def info(state):
    """Summarise a state file (.h5)."""
    from demcli.stages.base import load_stage_types
    from demcli.state import summarize

    load_stage_types()  # registers the stage-specific groups (gradation, polyhedra, ...)
    click.echo(summarize(state))


@cli.command()
@click.argument("runs", nargs=-1, required=True, type=click.Path(file_okay=False, exists=True))
@click.option("--record", help="Record file stem, e.g. vibrate_cycles (default: the seeds' figures that all "
                                "runs have).")
@click.option("-x", "x", help="Column along x (default: the first).")
@click.option("-y", "ys", multiple=True, help="Column(s) to plot: a comma list (-y a,b) or -y again "
                                             "(default: all others).")
@click.option("--out", default="compare", show_default=True, type=click.Path(file_okay=False),
              help="Folder for the PNG and CSV files.")
@click.option("--with", "earlier", multiple=True, type=click.Path(dir_okay=False, exists=True),
              help="A CSV written by an earlier compare: its curves join the figure with the same columns "
                   "(runs whose folders are gone).")
def compare(runs, record, x, ys, out, earlier):
    """Overlay a record of several RUNS (run folders) in one figure per column."""
    from demcli.compare import compare as _compare

    for path in _compare(runs, record=record, x=x, ys=ys, out=out, earlier=earlier):
        click.echo(path)


@cli.command()
@click.argument("case", type=click.Path(dir_okay=False))
@click.option("--vary", "varies", multiple=True, required=True, metavar="PATH=V1,V2,...",
              help="Values of one case path (as --set takes them); several --vary make a grid, and "
                   "+PATH=W1,W2,... varies a path together with the --vary before it (paired by position).")
@click.option("--metric", required=True, metavar="STAGE.TABLE.COLUMN[@REDUCER]",
              help="Column of records/<stage>_<table>.csv, reduced by @last (default), @first, @max, @min or @mean.")
@click.option("--reference", default="last", show_default=True, metavar="last|first|VARIANT",
              help="The finest variant: each --vary's last or first value, or a variant's folder name.")
@click.option("--realisations", metavar="PATH=V1,V2,...",
              help="Run every setting once per value (e.g. seed=1,2,3) and report each setting's mean, standard "
                   "deviation and the resolution of its difference from the reference (settings.csv, .png).")
@click.option("--set", "overrides", multiple=True, metavar="PATH=VALUE",
              help="In every variant: " + SET_HELP[0].lower() + SET_HELP[1:])
@click.option("--out", type=click.Path(file_okay=False), help="Study folder (default studies/<case name>).")
@click.option("--jobs", type=click.IntRange(min=1),
              help="Variants run at once (default: free cores // threads per job).")
@click.option("--threads-per-job", type=click.IntRange(min=1), default=1, show_default=True,
              help="Kernel threads of each variant's run.")
@click.option("--force", is_flag=True, help="Re-run variants that are up to date.")
@click.option("--cold", is_flag=True, help="Time each run as it comes, numba's first-call kernel loading included.")
@click.option("--quiet", is_flag=True, help="No progress lines; the table is still printed.")
def study(case, varies, metric, reference, realisations, overrides, out, jobs, threads_per_job, force, cold, quiet):
    """Run CASE once per variant and report metric, error and wall time (CSV, Markdown, PNG)."""
    from demcli.interrupts import stop_as_interrupt
    from demcli.study import run_study

    stop_as_interrupt()  # SIGTERM as Ctrl-C: stops the study, its workers too

    result = run_study(case, varies, metric, out=out, jobs=jobs, threads_per_job=threads_per_job,
                       reference=reference, overrides=overrides, force=force, cold=cold,
                       log=None if quiet else (lambda line: click.echo(line, err=True)), realisations=realisations)
    click.echo(result.markdown, nl=False)
    if not quiet:
        for path in result.files:
            click.echo(str(path), err=True)
    if result.failed:
        click.echo(f"{len(result.failed)} variant(s) failed; see the status column", err=True)


@cli.command()
@click.argument("sweep_file", metavar="SWEEP", type=click.Path(dir_okay=False))
@click.option("--workers", type=click.IntRange(min=1),
              help="Dask workers, one run each at a time (local: default the free cores // threads per run; "
                   "slurm/pbs: default one per run, at most 20).")
@click.option("--scheduler", metavar="ADDRESS", help="Use a running Dask scheduler, e.g. tcp://node1:8786.")
@click.option("--cluster", "cluster_type", type=click.Choice(["local", "slurm", "pbs"]),
              help="Where to start workers (default: the sweep file's cluster.type, else local).")
@click.option("--threads-per-run", type=click.IntRange(min=1), help="Kernel threads of each run (default 1).")
@click.option("--out", type=click.Path(file_okay=False), help="Output folder (default: the file's out, else sweeps/<name>).")
@click.option("--force", is_flag=True, help="Re-run stages that are up to date.")
@click.option("--resume", is_flag=True, help="Continue stages interrupted in an earlier sweep from their checkpoints.")
@click.option("--check", "check_only", is_flag=True, help="Validate the sweep and every run's case, list the runs; run nothing.")
@click.option("--quiet", is_flag=True, help="No progress lines; the status table is still printed.")
def sweep(sweep_file, workers, scheduler, cluster_type, threads_per_run, out, force, resume, check_only, quiet):
    """Run the cases, seeds and values of SWEEP (a YAML file) on Dask; exit 1 if any run failed."""
    from demcli.interrupts import stop_as_interrupt
    from demcli.sweep import check_sweep, run_sweep

    stop_as_interrupt()  # SIGTERM as Ctrl-C: the cluster closes, its runs checkpoint, the tables are written

    if check_only:
        check_sweep(sweep_file, out=out, echo=click.echo)
        return
    log = None if quiet else (lambda line: click.echo(line, err=True))
    result = run_sweep(sweep_file, out=out, workers=workers, scheduler=scheduler, cluster=cluster_type,
                       threads_per_run=threads_per_run, force=force, resume=resume, log=log)
    click.echo(result.table, nl=False)
    for line in result.warnings:
        click.echo(f"warning: {line}", err=True)
    if not quiet:
        for path in result.files:
            click.echo(str(path), err=True)
    if result.failed:
        n = len(result.runs)
        click.echo(f"{len(result.failed)} of {n} run{'s' if n != 1 else ''} failed; see the status column", err=True)
        sys.exit(1)


@cli.command()
@click.option("--fast", is_flag=True, help="One material and the ends of each sweep (the subset make test runs).")
@click.option("--out", type=click.Path(file_okay=False), default="docs", show_default=True,
              help="Folder of the report: validation.md and validation/chung_ooi_<n>.png.")
def validate(fast, out):
    """Run the Chung & Ooi (2011) benchmarks against their analytic limits and write the report;
    exit code 1 when a check is out of tolerance."""
    from pathlib import Path

    from demcli.errors import DemcliError
    from demcli.validation import validate as run_validation

    path, ok = run_validation(Path(out), fast=fast, log=click.echo)
    click.echo(f"report: {path}")
    if not ok:
        raise DemcliError(f"validation: a check is out of tolerance (see {path})")


@cli.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option("--sieves", metavar="LENGTHS",
              help="Square-hole apertures, ascending, a comma list with units as in case files: "
                   "16mm,25mm,31.5mm (a plain number is in m).")
@click.option("--method", type=click.Choice(SIEVE_METHODS), default="projection", show_default=True,
              help="Sieve size: projection (the least shadow's bounding rectangle, Shao et al. 2017), volume_sphere "
                   "or volume_cube (the sphere's diameter or cube's edge of equal volume), inertia_square (the "
                   "shadow across the least-inertia axis; polyhedra and spheres only).")
@click.option("--density", metavar="DENSITY",
              help="Density of the 3D particles of mesh and CSV files, e.g. 2650kg/m3 (state files carry their "
                   "masses); without it they are weighed by volume.")
@click.option("--target", metavar="PASSING",
              help="Target percent passing at each sieve, a comma list such as 0,10,60,100 (needs --sieves): "
                   "the class shares are compared with it.")
@click.option("--unit", default="m", show_default=True, metavar="LENGTH",
              help="Unit of the coordinates in mesh and CSV files, e.g. mm.")
@click.option("--out", default="sieve", show_default=True, type=click.Path(file_okay=False),
              help="Folder for particles.csv and, with --sieves, passing.csv, classes.csv and passing.png.")
def sieve(files, sieves, method, density, target, unit, out):
    """Size the particles of FILES and sieve them. FILES are state files (.h5), meshes (.obj, .stl, .ply,
    .off: each connected part one particle, sized as the convex hull of its vertices) or vertex tables
    (.csv with the header particle,x,y,z, or particle,x,y for 2D polygons)."""
    from demcli.sieving import sieve_files

    result = sieve_files(files, sieves=sieves, method=method, density=density, target=target, unit=unit, out=out)
    click.echo(result.summary())


@cli.command()
def warmup():
    """Compile (and cache) the engine kernels by running a tiny scene."""
    from demcli.check import warmup as _warmup

    click.echo(_warmup())


def main(argv=None):
    """Entry point of the ``demcli`` console script."""
    return cli.main(args=argv, prog_name="demcli", standalone_mode=True)


if __name__ == "__main__":
    sys.exit(main())
