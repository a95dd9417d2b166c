"""Command-line interface: `rafostrack track` and `rafostrack simulate`.

Thin: parse options, call the pipeline, report. A user mistake (`InputError`) prints one
line `rafostrack: error: ...` and exits with code 2; `--debug` shows the traceback.
"""

from __future__ import annotations

import sys
from functools import wraps
from pathlib import Path
from typing import Any

import click

from . import __version__
from .config import METHODS
from .errors import InputError


def _report_errors(func):
    """Turn user-facing errors into one line on stderr and exit code 2."""

    @wraps(func)
    def wrapper(*args, **kwargs):
        debug = click.get_current_context().find_root().params.get("debug", False)
        try:
            return func(*args, **kwargs)
        except InputError as exc:
            if debug:
                raise
            click.echo(f"rafostrack: error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # e.g. output directory not writable
            if debug:
                raise
            where = f"{exc.filename}: " if exc.filename else ""
            click.echo(f"rafostrack: error: {where}{exc.strerror or exc}", err=True)
            sys.exit(2)

    return wrapper


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


def _overrides(**flags: Any) -> dict[str, dict[str, Any]]:
    """Config overrides from command-line flags that were given (section, key)."""
    where = {
        "method": "filter",
        "particles": "filter",
        "seed": "filter",
        "clutter_rate": "model",
        "p_detect": "model",
        "toa_sigma_s": "model",
    }
    out: dict[str, dict[str, Any]] = {}
    for key, value in flags.items():
        if value is not None:
            out.setdefault(where[key], {})[key] = value
    return out


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="rafostrack")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
def main(debug: bool) -> None:
    """Track RAFOS floats from unlabelled, ranked arrival times."""


@main.command()
@click.argument("float_file", type=click.Path(path_type=Path))
@click.option(
    "--beacons",
    type=click.Path(path_type=Path),
    help="Beacon table (default: beacons.csv beside FLOAT_FILE).",
)
@click.option("--floats", type=click.Path(path_type=Path), help="Float table (default: floats.csv beside FLOAT_FILE).")
@click.option("--launch", callback=_parse_launch, metavar="LAT,LON", help="Override the launch position.")
@click.option("--config", "config_file", type=click.Path(path_type=Path), help="Extra TOML config layer.")
@click.option("--method", type=click.Choice(METHODS), help="Association method (default from config: exact).")
@click.option("--particles", type=int, help="Number of particles.")
@click.option("--seed", type=int, help="Random seed.")
@click.option("--clutter-rate", type=float, help="Expected clutter signals per window.")
@click.option("--p-detect", type=float, help="Detection probability of a source's signal.")
@click.option("--toa-sigma-s", type=float, help="Arrival-time noise sd (s).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("out"), show_default=True)
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@_report_errors
def track(float_file, beacons, floats, launch, config_file, out_dir, no_plots, **flags) -> None:
    """Label every TOA of FLOAT_FILE and estimate the float's track."""
    from .pipeline import TrackInputs, track_float

    inputs = TrackInputs(
        float_path=float_file,
        beacons_path=beacons,
        floats_path=floats,
        launch=launch,
        config_files=(config_file,) if config_file else (),
        overrides=_overrides(**flags),
    )
    result = track_float(inputs, out_dir, plots=not no_plots)
    for message in result.run["warnings"]:
        click.echo(f"rafostrack: warning: {message}", err=True)
    counts = result.run["counts"]
    click.echo(
        f"{result.float_id}: {counts['windows']} windows, {counts['toas']} TOAs "
        f"({counts['labelled_beacon']} labelled to beacons, {counts['labelled_clutter']} clutter), "
        f"{result.run['runtime_s']:.1f} s -> {result.out_dir}"
    )


@main.command()
@click.argument("out_dir", type=click.Path(path_type=Path))
@click.option("--scenario", type=click.Choice(["dimes", "synthetic"]), default="synthetic", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--days", type=int, help="Truncate each float to this many days.")
@click.option("--n-floats", type=int, default=1, show_default=True, help="Floats (synthetic scenario).")
@click.option("--clutter-rate", type=float, help="Expected clutter signals per window.")
@click.option("--p-detect", type=float, help="Detection probability.")
@click.option("--toa-sigma-s", type=float, help="Arrival-time noise sd (s).")
@click.option("--config", "config_file", type=click.Path(path_type=Path), help="TOML with a [model] table.")
@_report_errors
def simulate(out_dir, scenario, seed, days, n_floats, config_file, **flags) -> None:
    """Write a simulated mission (inputs plus truth/) to OUT_DIR."""
    import numpy as np

    from .config import load_config
    from .simulate import dimes_scenario, simulate_mission, synthetic_scenario, write_mission

    config = load_config((config_file,) if config_file else (), _overrides(**flags))
    rng = np.random.default_rng(seed)
    if scenario == "dimes":
        beacons, floats = dimes_scenario()
    else:
        beacons, floats = synthetic_scenario(days=days or 60, n_floats=n_floats, rng=rng)
    mission = simulate_mission(beacons, floats, config.model, rng, days=days)
    write_mission(mission, out_dir)
    click.echo(f"simulated {len(mission.floats)} float(s) -> {out_dir}")
