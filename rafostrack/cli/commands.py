"""The commands: `rafostrack track`, `legs`, `batch`, `summary`, `simulate` and `config`.

Thin: parse options, call the pipeline, report. Each command imports the pipeline when it
runs, not at start-up.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .. import __version__
from ..errors import InputError
from .errors import RafostrackGroup, debug_option, report_errors
from .options import (
    RegistryChoice,
    arrival_formats,
    check_float_file,
    config_options,
    config_overrides,
    float_inputs,
    refuse_method,
    track_inputs,
)


@click.group(cls=RafostrackGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="rafostrack")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
def main(debug: bool) -> None:
    """Track RAFOS floats from unlabelled, ranked arrival times."""


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
    "--threads",
    type=click.IntRange(min=1),
    help="Kernel threads (default: the cores idle when the run starts; the output is the same bits either way).",
)
@click.option(
    "--input-format",
    type=RegistryChoice(arrival_formats),
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
@report_errors
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
    threads,
    **flags,
):
    """Label every TOA of FLOAT_FILE and estimate the float's track."""
    from ..io.output_formats import parse_formats
    from ..model.parallel import kernel_threads, track_threads
    from ..run.one_float import track_float

    refuse_method(method)
    check_float_file(float_file)
    formats = parse_formats(output_format)
    overrides = config_overrides(**flags, smooth=False if no_smooth else None)
    inputs = track_inputs(float_file, beacons, floats, launch, config_file, overrides, input_format)
    from ..run import progress as progress_module

    progress = progress_module.progress_for(sys.stderr, label=float_file.stem)
    try:
        with kernel_threads(track_threads(threads)):
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
@report_errors
def legs(float_file, beacons, floats, launch, config_file, iterations, out_dir, no_plots, **flags):
    """Fit straight legs (speed, heading, duration) to FLOAT_FILE's arrival times by MCMC.

    Tracks the float with the particle smoother first (as `track` does), then fits the leg
    model to every window's arrival times, started from the smoother's track; writes
    legs.parquet, legs_track.parquet, legs.png and legs_run.json to OUT/<float_id>/.
    """
    from ..legs.floats import legs_float

    check_float_file(float_file)
    overrides = config_overrides(**flags)
    if iterations is not None:
        overrides.setdefault("legs", {})["iterations"] = iterations
    inputs = track_inputs(float_file, beacons, floats, launch, config_file, overrides)
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
@report_errors
def simulate(out_dir, scenario, seed, days, n_floats, config_file, **flags) -> None:
    """Write a simulated mission (inputs plus truth/) to OUT_DIR."""
    import numpy as np

    from ..config import load_config
    from ..sim.mission_writer import write_mission
    from ..sim.scenarios import DIMES_FLOATS, dimes_scenario, synthetic_scenario
    from ..sim.simulate import simulate_mission

    config = load_config((config_file,) if config_file else (), config_overrides(**flags))
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
@click.option(
    "--no-array-fit",
    is_flag=True,
    help="Do not fit each mission's sound-source array on all its floats (nor track them again with it): "
    "each float checks the tables alone.",
)
@debug_option
@report_errors
def batch(roots, out_dir, jobs, force, scheduler, config_file, method, no_plots, no_array_fit, **flags) -> None:
    """Track every float of the mission directories under ROOTs, skipping unchanged ones.

    Exit code 0 when every float succeeded, 1 when some failed, 2 on a usage error
    (including OUT being locked by another batch run).
    """
    from ..batch import run_batch

    refuse_method(method)
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
        overrides=config_overrides(**flags),
        plots=not no_plots,
        array_fit=not no_array_fit,
    )
    click.echo(result.summary)
    sys.exit(result.exit_code)


@main.command()
@click.argument("out_root", metavar="OUT", type=click.Path(path_type=Path))
@debug_option
@report_errors
def summary(out_root) -> None:
    """Write the mission overview of an existing output tree OUT (the output root of `batch`,
    or the --out folder of `track`): overview.html, overview.csv and overview.png in OUT,
    the floats that need a look first. Exit code 2 when OUT holds no tracked float."""
    from ..batch.overview import OK, summarise_tree, write_overview

    overview = summarise_tree(out_root)
    html_path = write_overview(
        overview, notice=lambda message: click.echo(f"rafostrack: warning: {message}", err=True)
    )[0]
    click.echo(f"{len(overview.rows)} floats, {len(overview.rows) - overview.count(OK)} need a look -> {html_path}")


@main.command("config")
@click.argument("mission", required=False, type=click.Path(path_type=Path))
@click.option("--config", "config_file", type=click.Path(path_type=Path), help="Extra TOML config layer.")
@config_options("likelihood", "engine", "motion", "particles", "seed", "clutter_rate", "p_detect", "toa_sigma_s")
@debug_option
@report_errors
def show_config(mission, config_file, **flags) -> None:
    """Print the effective configuration for MISSION (a mission directory or a float file in
    it; default: none, the package defaults), each key with the layer it came from."""
    from ..io.config_report import COMMAND_LINE, layered_config, render
    from ..run.one_float import MISSION_CONFIG

    files: list[Path] = []
    if mission is not None:
        if not mission.exists():
            raise InputError(f"{mission}: not found; expected a mission directory or a float file in one")
        mission_toml = (mission if mission.is_dir() else mission.parent) / MISSION_CONFIG
        if mission_toml.is_file():
            files.append(mission_toml)
    if config_file is not None:
        files.append(config_file)
    overrides = config_overrides(**flags)
    config, sources = layered_config(files, overrides)
    names = ["default", *(str(p) for p in files), *([COMMAND_LINE] if overrides else [])]
    click.echo(render(config, sources, names), nl=False)
