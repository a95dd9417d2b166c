"""The options the commands share: a float's inputs, the flags that set a config key, the
choices a registry holds (read when an option needs them, not at start-up)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ..errors import InputError

if TYPE_CHECKING:  # the pipeline is imported when a command runs, not at start-up
    from ..run.one_float import TrackInputs


class RegistryChoice(click.Choice):
    """A `click.Choice` of the names a registry holds, read when the option first needs them
    (to check a value, to show the help), so that the command line starts without importing
    the pipeline."""

    def __init__(self, names: Callable[[], Iterable[str]]) -> None:
        self._names = names
        self._choices: tuple[str, ...] | None = None
        self.case_sensitive = True

    @property
    def choices(self) -> tuple[str, ...]:
        if self._choices is None:
            self._choices = tuple(self._names())
        return self._choices

    @choices.setter
    def choices(self, names: Iterable[str]) -> None:
        self._choices = tuple(names)


def arrival_formats() -> list[str]:
    """The `--input-format` values: the arrival readers' formats, in their registry's order."""
    from ..io import formats

    return formats("arrivals")


def parse_launch(_ctx, _param, value: str | None) -> tuple[float, float] | None:
    """`--launch LAT,LON` as (lat, lon) in degrees, checked."""
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
    from ..config import field_type, key_comment

    def decorate(func):
        for flag in reversed(flags):
            section, key = CONFIG_FLAGS[flag]
            kind = field_type(section, key)
            help_text = f"[{section}] {key}: {key_comment(section, key)}"
            func = click.option(f"--{flag.replace('_', '-')}", flag, type=kind, help=help_text)(func)
        return func

    return decorate


def config_overrides(**flags: Any) -> dict[str, dict[str, Any]]:
    """Config overrides from command-line flags that were given (section, key)."""
    where = {**CONFIG_FLAGS, "smooth": ("smoother", "enabled")}
    out: dict[str, dict[str, Any]] = {}
    for flag, value in flags.items():
        if value is not None:
            section, key = where[flag]
            out.setdefault(section, {})[key] = value
    return out


def refuse_method(method: str | None) -> None:
    """`--method` was split into `--likelihood` and `--engine`: say what to write instead."""
    if method is not None:
        from ..config import METHODS

        likelihood, engine = METHODS.get(method, METHODS["exact"])
        raise InputError(f"--method was split into two options: use --likelihood {likelihood} --engine {engine}")


def check_float_file(float_file: Path) -> None:
    """A directory given as FLOAT_FILE is named as one (not "file not found"), with the
    command that tracks every float in it."""
    from ..io import check_arrival_file

    check_arrival_file(float_file, f"; to track every float in it: rafostrack batch {float_file} --out OUT")


def track_inputs(
    float_file: Path,
    beacons: Path | None,
    floats: Path | None,
    launch: tuple[float, float] | None,
    config_file: Path | None,
    overrides: dict[str, dict[str, Any]],
    input_format: str | None = None,
) -> TrackInputs:
    """`run.one_float.TrackInputs` from the options of `float_inputs`."""
    from ..run.one_float import TrackInputs

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
            click.option("--launch", callback=parse_launch, metavar="LAT,LON", help="Override the launch position."),
            click.option("--config", "config_file", type=click.Path(path_type=Path), help="Extra TOML config layer."),
        ]
    ):
        command = option(command)
    return command
