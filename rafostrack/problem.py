"""One float's problem: what a pass of the tracker needs besides the arrival record.

The beacon table, the float's description, the configuration and the model values that
replace configured ones always travel together: the tracker (`run.one_pass.Tracker`), the
method (`run.method.track_record`) and calibration (`calibrate.calibrate`) each take one
`FloatProblem`. The configuration is the user's, never rewritten: the keys the user set
travel inside it (`Config.explicit`), and what a pass tracks with instead of a configured
value (calibration's estimates, the robust first pass's wider TOA noise) is a typed
`ModelValues` beside it. A calibration gives the calibrated problem
(`calibrate.Calibration.calibrated`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from .config import Config
from .domain import BeaconTable, FloatInfo


def _value(section: str, decimals: int) -> Any:
    """A model value of `[section]`, reported and tracked with at `decimals` places."""
    return field(default=None, metadata={"section": section, "decimals": decimals})


@dataclass(frozen=True)
class ModelValues:
    """Values of `[model]` and `[motion]` a pass tracks with in place of the configured ones;
    None: the configured value. Calibration rounds each to its `decimals`, as run.json
    reports it: the reported values, given back as configuration, reproduce the track."""

    sound_speed_m_s: float | None = _value("model", 2)
    toa_sigma_s: float | None = _value("model", 3)
    mean_current_east_km_per_day: float | None = _value("motion", 3)
    mean_current_north_km_per_day: float | None = _value("motion", 3)
    velocity_sd_km_per_day: float | None = _value("motion", 3)
    decorrelation_days: float | None = _value("motion", 2)
    diffusion_km_per_day: float | None = _value("motion", 3)
    multipath_fraction: float | None = _value("model", 4)
    multipath_delay_s: float | None = _value("model", 2)
    echo_fraction: float | None = _value("model", 4)
    clutter_rate: float | None = _value("model", 3)

    @staticmethod
    def keys() -> tuple[tuple[str, str], ...]:
        """Every (section, key) a `ModelValues` can set."""
        return tuple((f.metadata["section"], f.name) for f in dataclasses.fields(ModelValues))

    @classmethod
    def rounded(cls, values: dict[str, float], explicit: frozenset[tuple[str, str]]) -> ModelValues:
        """`values` (by key) each rounded to its decimals (by the value's own `round`: numpy's
        for a numpy float), leaving out the keys the user set."""
        kept = {}
        for f in dataclasses.fields(cls):
            if f.name in values and (f.metadata["section"], f.name) not in explicit:
                kept[f.name] = float(round(values[f.name], f.metadata["decimals"]))
        return cls(**kept)

    def items(self) -> list[tuple[tuple[str, str], float]]:
        """The values set, as ((section, key), value) in field order."""
        values = [((f.metadata["section"], f.name), getattr(self, f.name)) for f in dataclasses.fields(self)]
        return [(key, value) for key, value in values if value is not None]

    def merged(self, later: ModelValues) -> ModelValues:
        """These values with those `later` sets in their place."""
        return dataclasses.replace(self, **{key: value for (_, key), value in later.items()})

    def applied(self, config: Config) -> Config:
        """`config`'s sections with these values in place (the user's `explicit` keys as they are)."""
        sections: dict[str, dict[str, float]] = {}
        for (section, key), value in self.items():
            sections.setdefault(section, {})[key] = value
        if not sections:
            return config
        return dataclasses.replace(
            config, **{name: dataclasses.replace(getattr(config, name), **keys) for name, keys in sections.items()}
        )


@dataclass(frozen=True)
class FloatProblem:
    """One float's beacons, description and configuration (with the keys the user set), and
    the model values that replace configured ones (none by default)."""

    beacons: BeaconTable
    info: FloatInfo
    config: Config
    model: ModelValues = ModelValues()

    def with_config(self, config: Config) -> FloatProblem:
        """The same float and beacons under `config`."""
        return dataclasses.replace(self, config=config)

    @property
    def tracking_config(self) -> Config:
        """The configuration a pass's components are built from: the user's, with `model` in place."""
        return self.model.applied(self.config)
