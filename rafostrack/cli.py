"""Command-line interface: `rafostrack track`, `legs`, `batch`, `summary`, `simulate` and `config`.

Thin: parse options, call the pipeline, report. A user mistake (`InputError`) prints one
line `rafostrack: error: ...` and exits with code 2; `--debug` shows the traceback.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from . import __version__
from .errors import InputError

if TYPE_CHECKING:  # the pipeline is imported when a command runs, not at start-up
    from .run.one_float import TrackInputs


def _report_errors(func):
    """Turn errors into one line on stderr, no traceback (unless `--debug`): user-facing
    errors (`InputError`, an unwritable output path) exit with code 2, unexpected ones with 1.
    An `out_dir` argument is checked before any work."""

    @wraps(func)
    def wrapper(*args, **kwargs):
        from .io.outdir import check_output_dir

        debug = _debug(click.get_current_context())
        out_dir = kwargs.get("out_dir")
        try:
            if out_dir is not None:
                check_output_dir(out_dir)
            return func(*args, **kwargs)
        except InputError as exc:
            if debug:
                raise
            click.echo(f"rafostrack: error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # e.g. output directory not writable, disk full
            if debug:
                raise
            name = Path(exc.filename) if exc.filename else None
            where, expected = (f"{name}: " if name else ""), ""
            if out_dir is not None and name is not None and (name == Path(out_dir) or Path(out_dir) in name.parents):
                where = f"cannot write output directory {out_dir}: {where}"
                expected = "; expected a writable directory with room to write"
            reason = " ".join(str(exc.strerror or exc).splitlines())
            click.echo(f"rafostrack: error: {where}{reason}{expected}", err=True)
            sys.exit(2)
        except (click.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except Exception as exc:  # a bug, not a user mistake: still one line unless --debug
            if debug:
                raise
            reason = " ".join(str(exc).splitlines()) or "no message"
            click.echo(
                f"rafostrack: internal error: {type(exc).__name__}: {reason} (rerun with --debug for the traceback)",
                err=True,
            )
            sys.exit(1)

    return wrapper


def _debug(ctx: click.Context) -> bool:
    """Whether `--debug` was given, before or after the subcommand."""
    return bool(ctx.find_root().params.get("debug", False) or ctx.meta.get("rafostrack.debug", False))


def _set_debug(ctx: click.Context, _param: click.Parameter, value: bool) -> bool:
    if value:
        ctx.meta["rafostrack.debug"] = True
    return value


def debug_option(func):
    """`--debug` on a subcommand too (`rafostrack track F --debug`), as on the root."""
    return click.option(
        "--debug",
        is_flag=True,
        expose_value=False,
        callback=_set_debug,
        help="Show tracebacks instead of one-line errors.",
    )(func)


class RafostrackGroup(click.Group):
    """The root command. A usage error (a bad option value, an unknown option or command, a
    missing argument) prints the documented one line `rafostrack: error: ...` and exits
    with code 2, like every other user mistake; with `--debug`, click's full usage text."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):  # type: ignore[override]
        argv = list(sys.argv[1:] if args is None else args)
        try:
            rv = super().main(argv, "rafostrack", complete_var, standalone_mode=False, **extra)
        except click.ClickException as exc:
            if "--debug" in argv:
                exc.show()
            else:
                click.echo(f"rafostrack: error: {_usage_message(exc)}", err=True)
            sys.exit(exc.exit_code)
        except click.exceptions.Abort:
            click.echo("rafostrack: aborted", err=True)
            sys.exit(1)
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


def _usage_message(exc: click.ClickException) -> str:
    """One line: the command, click's message, and where to find the usage."""
    message = " ".join(exc.format_message().split())
    ctx = getattr(exc, "ctx", None)
    if ctx is None:
        return message
    path = ctx.command_path
    where = "" if ctx.parent is None else f"{path.split(' ', 1)[-1]}: "
    return f"{where}{message} (see '{path} --help')"


def _parse_launch(_ctx, _param, value: str | None) -> tuple[float, float] | None:
    if value is None:
        return None
    try:
        lat, lon = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected LAT,LON in degrees (e.g. -56.3,-105.0), got {value!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 360):
        raise click.BadParameter(f"latitude must be in [-90, 90] and longitude in [-180, 360], got {value!r}")
    return lat, lon


# Command-line flags that set a config key: flag -> (section, key). The flag's type is the
# config field's; its value is checked like any other config layer (`rafostrack.config`).
CONFIG_FLAGS: dict[str, tuple[str, str]] = {
    "likelihood": ("filter", "likelihood"),
    "engine": ("filter", "engine"),
    "motion": ("motion", "model"),
    "particles": ("filter", "particles"),
    "seed": ("filter", "seed"),
    "clutter_rate": ("model", "clutter_rate"),
    "p_detect": ("model", "p_detect"),
    "toa_sigma_s": ("model", "toa_sigma_s"),
    "bathymetry": ("context", "bathymetry"),
}


def config_options(*flags: str):
    """Decorator adding `--<flag>` options for config keys, typed and described from the
    config field and its comment in default.toml."""
    from .config import field_type, key_comment

    def decorate(func):
        for flag in reversed(flags):
            section, key = CONFIG_FLAGS[flag]
            kind = field_type(section, key)
            help_text = f"[{section}] {key}: {key_comment(section, key)}"
            func = click.option(f"--{flag.replace('_', '-')}", flag, type=kind, help=help_text)(func)
        return func

    return decorate


def _overrides(**flags: Any) -> dict[str, dict[str, Any]]:
    """Config overrides from command-line flags that were given (section, key)."""
    where = {**CONFIG_FLAGS, "smooth": ("smoother", "enabled")}
    out: dict[str, dict[str, Any]] = {}
    for flag, value in flags.items():
        if value is not None:
            section, key = where[flag]
            out.setdefault(section, {})[key] = value
    return out


def _refuse_method(method: str | None) -> None:
    """`--method` was split into `--likelihood` and `--engine`: say what to write instead."""
    if method is not None:
        from .config import METHODS

        likelihood, engine = METHODS.get(method, METHODS["exact"])
        raise InputError(f"--method was split into two options: use --likelihood {likelihood} --engine {engine}")


@click.group(cls=RafostrackGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="rafostrack")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
def main(debug: bool) -> None:
    """Track RAFOS floats from unlabelled, ranked arrival times."""


def _check_float_file(float_file: Path) -> None:
    """A directory given as FLOAT_FILE is named as one (not "file not found"), with the
    command that tracks every float in it."""
    from .io import check_arrival_file

    check_arrival_file(float_file, f"; to track every float in it: rafostrack batch {float_file} --out OUT")


def _track_inputs(
    float_file: Path,
    beacons: Path | None,
    floats: Path | None,
    launch: tuple[float, float] | None,
    config_file: Path | None,
    overrides: dict[str, dict[str, Any]],
    input_format: str | None = None,
) -> TrackInputs:
    """`run.one_float.TrackInputs` from the options of `float_inputs`."""
    from .run.one_float import TrackInputs

    return TrackInputs(
        float_path=float_file,
        beacons_path=beacons,
        floats_path=floats,
        launch=launch,
        config_files=(config_file,) if config_file else (),
        overrides=overrides,
        input_format=input_format,
    )


def float_inputs(command: Callable[..., Any]) -> Callable[..., Any]:
    """The inputs of a one-float command (track, legs): FLOAT_FILE and the tables beside it."""
    for option in reversed(
        [
            click.argument("float_file", type=click.Path(path_type=Path)),
            click.option(
                "--beacons",
                type=click.Path(path_type=Path),
                help="Beacon table (default: beacons.csv beside FLOAT_FILE).",
            ),
            click.option(
                "--floats", type=click.Path(path_type=Path), help="Float table (default: floats.csv beside FLOAT_FILE)."
            ),
            click.option("--launch", callback=_parse_launch, metavar="LAT,LON", help="Override the launch position."),
            click.option("--config", "config_file", type=click.Path(path_type=Path), help="Extra TOML config layer."),
        ]
    ):
        command = option(command)
    return command


@main.command()
@float_inputs
@config_options(
    "likelihood", "engine", "motion", "particles", "seed", "clutter_rate", "p_detect", "toa_sigma_s", "bathymetry"
)
@click.option("--method", hidden=True, help="Removed: see --likelihood and --engine.")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("out"), show_default=True)
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@click.option("--no-smooth", is_flag=True, help="Filter only: no backward smoothing over the mission.")
@click.option("--also-filtered", is_flag=True, help="Also write the filtered estimate (*_filtered.parquet).")
@click.option(
    "--input-format",
    type=click.Choice(["csv", "artoa-mat", "argo-aux"]),
    help="The float file's format (default: by its name: *.csv, *.itm / rf*toa.mat, *_Rtraj_aux.nc).",
)
@click.option(
    "--format",
    "output_format",
    default="parquet",
    show_default=True,
    metavar="LIST",
    help="Output formats, comma-separated: parquet, csv, netcdf (CF track.nc and labels.nc), rfc (ARTOA track text).",
)
@debug_option
@_report_errors
def track(
    float_file,
    beacons,
    floats,
    launch,
    config_file,
    out_dir,
    no_plots,
    no_smooth,
    also_filtered,
    method,
    output_format,
    input_format,
    **flags,
):
    """Label every TOA of FLOAT_FILE and estimate the float's track."""
    from .io.output_formats import parse_formats
    from .run.one_float import track_float

    _refuse_method(method)
    _check_float_file(float_file)
    formats = parse_formats(output_format)
    overrides = _overrides(**flags, smooth=False if no_smooth else None)
    inputs = _track_inputs(float_file, beacons, floats, launch, config_file, overrides, input_format)
    from .run import progress as progress_module

    progress = progress_module.progress_for(sys.stderr, label=float_file.stem)
    try:
        result = track_float(
            inputs,
            out_dir,
            plots=not no_plots,
            also_filtered=also_filtered,
            progress=progress,
            formats=formats,
            notice=lambda message: click.echo(f"rafostrack: warning: {message}", err=True),
        )
    finally:
        progress.close()
    for message in result.run["warnings"]:
        click.echo(f"rafostrack: warning: {message}", err=True)
    if result.run["warnings"]:
        n = len(result.run["warnings"])
        click.echo(f"rafostrack: {n} warning(s), also listed in {result.out_dir / 'run.json'}", err=True)
    counts = result.run["counts"]
    status = ", ".join(f"{n} {name}" for name, n in counts["status"].items())
    click.echo(
        f"{result.float_id}: {counts['windows']} windows ({status}), {counts['toas']} TOAs "
        f"({counts['labelled_beacon']} labelled to beacons, {counts['labelled_clutter']} clutter), "
        f"{result.run['runtime_s']:.1f} s -> {result.out_dir}"
    )


@main.command()
@float_inputs
@config_options("likelihood", "engine", "motion", "particles", "seed", "clutter_rate", "p_detect", "toa_sigma_s")
@click.option("--iterations", type=click.IntRange(min=100), help="[legs] iterations: MCMC iterations of the leg fit.")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("out"), show_default=True)
@click.option("--no-plots", is_flag=True, help="Skip the PNG plot.")
@_report_errors
def legs(float_file, beacons, floats, launch, config_file, iterations, out_dir, no_plots, **flags):
    """Fit straight legs (speed, heading, duration) to FLOAT_FILE's arrival times by MCMC.

    Tracks the float with the particle smoother first (as `track` does), then fits the leg
    model to every window's arrival times, started from the smoother's track; writes
    legs.parquet, legs_track.parquet, legs.png and legs_run.json to OUT/<float_id>/.
    """
    from .legs.floats import legs_float

    _check_float_file(float_file)
    overrides = _overrides(**flags)
    if iterations is not None:
        overrides.setdefault("legs", {})["iterations"] = iterations
    inputs = _track_inputs(float_file, beacons, floats, launch, config_file, overrides)
    result = legs_float(inputs, out_dir, plots=not no_plots)
    for message in result.run["warnings"]:
        click.echo(f"rafostrack: warning: {message}", err=True)
    k = result.run["legs"]
    click.echo(
        f"{result.float_id}: {result.run['windows']} windows, {k['map']} legs (posterior {k['posterior_q05']}-"
        f"{k['posterior_q95']}), {result.run['runtime_s']:.1f} s -> {result.out_dir}"
    )


@main.command()
@click.argument("out_dir", type=click.Path(path_type=Path))
@click.option("--scenario", type=click.Choice(["dimes", "synthetic"]), default="synthetic", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--days", type=click.IntRange(min=1), help="Truncate each float to this many days.")
@click.option(
    "--n-floats",
    type=click.IntRange(min=1),
    help="Floats to simulate (default: 1 for synthetic; for dimes all 3, the most it has).",
)
@config_options("clutter_rate", "p_detect", "toa_sigma_s")
@click.option("--config", "config_file", type=click.Path(path_type=Path), help="TOML with a [model] table.")
@debug_option
@_report_errors
def simulate(out_dir, scenario, seed, days, n_floats, config_file, **flags) -> None:
    """Write a simulated mission (inputs plus truth/) to OUT_DIR."""
    import numpy as np

    from .config import load_config
    from .sim.mission_writer import write_mission
    from .sim.scenarios import DIMES_FLOATS, dimes_scenario, synthetic_scenario
    from .sim.simulate import simulate_mission

    config = load_config((config_file,) if config_file else (), _overrides(**flags))
    rng = np.random.default_rng(seed)
    if scenario == "dimes":
        if n_floats is not None and n_floats > len(DIMES_FLOATS):
            known = ", ".join(f"float{f}" for f in DIMES_FLOATS)
            raise InputError(
                f"--n-floats {n_floats}: the dimes scenario has {len(DIMES_FLOATS)} floats ({known}); "
                f"expected at most {len(DIMES_FLOATS)} (--scenario synthetic makes any number)"
            )
        beacons, floats = dimes_scenario(DIMES_FLOATS[: n_floats or len(DIMES_FLOATS)])
    else:
        beacons, floats = synthetic_scenario(days=days or 60, n_floats=n_floats or 1, rng=rng)
    mission = simulate_mission(beacons, floats, config.model, rng, days=days)
    write_mission(mission, out_dir)
    click.echo(f"simulated {len(mission.floats)} float(s) -> {out_dir}")


@main.command()
@click.argument("roots", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Output root (mirrors ROOTs).")
@click.option("--jobs", type=click.IntRange(min=1), help="Worker processes (default: the number of cores).")
@click.option("--force", is_flag=True, help="Reprocess every float, even unchanged ones.")
@click.option("--scheduler", metavar="ADDRESS", help="Run on this Dask scheduler (tcp://host:8786) instead.")
@click.option("--config", "config_file", type=click.Path(path_type=Path), help="Extra TOML config layer.")
@config_options("likelihood", "engine", "motion", "bathymetry")
@click.option("--method", hidden=True, help="Removed: see --likelihood and --engine.")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@debug_option
@_report_errors
def batch(roots, out_dir, jobs, force, scheduler, config_file, method, no_plots, **flags) -> None:
    """Track every float of the mission directories under ROOTs, skipping unchanged ones.

    Exit code 0 when every float succeeded, 1 when some failed, 2 on a usage error
    (including OUT being locked by another batch run).
    """
    from .batch import run_batch

    _refuse_method(method)
    for root in roots:
        if not root.exists():
            raise InputError(f"{root}: does not exist; expected a directory holding missions")
    result = run_batch(
        roots,
        out_dir,
        jobs=jobs,
        force=force,
        scheduler=scheduler,
        config_file=config_file,
        overrides=_overrides(**flags),
        plots=not no_plots,
    )
    click.echo(result.summary)
    sys.exit(result.exit_code)


@main.command()
@click.argument("out_root", metavar="OUT", type=click.Path(path_type=Path))
@debug_option
@_report_errors
def summary(out_root) -> None:
    """Write the mission overview of an existing output tree OUT (the output root of `batch`,
    or the --out folder of `track`): overview.html, overview.csv and overview.png in OUT,
    the floats that need a look first. Exit code 2 when OUT holds no tracked float."""
    from .batch.overview import OK, summarise_tree, write_overview

    overview = summarise_tree(out_root)
    html_path = write_overview(overview)[0]
    click.echo(f"{len(overview.rows)} floats, {len(overview.rows) - overview.count(OK)} need a look -> {html_path}")


@main.command("config")
@click.argument("mission", required=False, type=click.Path(path_type=Path))
@click.option("--config", "config_file", type=click.Path(path_type=Path), help="Extra TOML config layer.")
@config_options("likelihood", "engine", "motion", "particles", "seed", "clutter_rate", "p_detect", "toa_sigma_s")
@debug_option
@_report_errors
def show_config(mission, config_file, **flags) -> None:
    """Print the effective configuration for MISSION (a mission directory or a float file in
    it; default: none, the package defaults), each key with the layer it came from."""
    from .errors import InputError
    from .io.config_report import COMMAND_LINE, layered_config, render
    from .run.one_float import MISSION_CONFIG

    files: list[Path] = []
    if mission is not None:
        if not mission.exists():
            raise InputError(f"{mission}: not found; expected a mission directory or a float file in one")
        mission_toml = (mission if mission.is_dir() else mission.parent) / MISSION_CONFIG
        if mission_toml.is_file():
            files.append(mission_toml)
    if config_file is not None:
        files.append(config_file)
    overrides = _overrides(**flags)
    config, sources = layered_config(files, overrides)
    names = ["default", *(str(p) for p in files), *([COMMAND_LINE] if overrides else [])]
    click.echo(render(config, sources, names), nl=False)
