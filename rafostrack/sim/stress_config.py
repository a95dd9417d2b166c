"""The stress generator's knobs (`rafostrack.sim.stress`): every phenomenon of its missions,
its ranges, and whether it is on (for ablation)."""

from __future__ import annotations

from dataclasses import dataclass

from .faults import CLOCK_KINDS, check_kinds


@dataclass(frozen=True)
class StressConfig:
    """The phenomena and their ranges; each can be turned off (for ablation)."""

    days: int = 240
    max_signals: int = 4
    clutter_rate: float = 2.0
    # drift
    jet: bool = True
    eddies: bool = True
    eddy_count: int = 14  # within ~700 km of the launch
    eddy_radius_km: tuple[float, float] = (25.0, 60.0)
    eddy_swirl_km_per_day: tuple[float, float] = (5.0, 15.0)
    noise_velocity_km_per_day: float = 1.5
    noise_timescale_days: float = 3.0
    # records
    gaps: bool = True
    gap_count: tuple[int, int] = (1, 3)
    gap_days: tuple[int, int] = (3, 8)
    missing_day_prob: float = 0.03
    empty_window_prob: float = 0.02
    # detection
    fading: bool = True
    p_detect: tuple[float, float] = (0.75, 0.97)
    range_km: tuple[float, float] = (700.0, 1300.0)
    falloff_km: tuple[float, float] = (60.0, 150.0)
    bad_propagation: bool = True
    # multipath
    multipath: bool = True
    multipath_fraction: tuple[float, float] = (0.03, 0.12)
    # sources
    outage: bool = True
    outage_days: tuple[int, int] = (20, 60)
    source_drift_s_per_day: float = 0.01
    # float clock
    clock_wander: bool = True
    clock_wander_s: tuple[float, float] = (1.0, 3.0)
    # The true clock's offset at the end (s), uniform in this range and written in floats.csv,
    # e.g. (-40, 40) (the public DIMES floats' end offsets: -66..+45 s, median -3 s); None:
    # within +-2 s like the launch's. The clock faults need it.
    clock_end_offset_s: tuple[float, float] | None = None
    # Share of the floats that never surfaced: no end fix and no end clock in floats.csv.
    never_surfaced_share: float = 0.0
    # Metadata faults written in the tables (`rafostrack.sim.faults.FAULT_KINDS`), and the
    # share of the floats each float kind hits.
    faults: tuple[str, ...] = ()
    fault_float_share: float = 1.0
    # sound speed
    sound_speed_mismatch: bool = True
    beacon_sound_speed_sd_m_s: float = 2.0
    # TOA noise and clutter
    toa_sd_s: tuple[float, float] = (1.5, 3.0)
    heavy_tails: bool = True
    burst_prob: float = 0.03
    # Clutter's density over the window falls linearly to (1 - clutter_taper) of its start
    # at the window's end (0: uniform, as the tracker's model has it and the window check
    # assumes, `rafostrack.calibrate.window_check`; 1: none at the very end).
    clutter_taper: float = 0.0
    # Coverage: a float whose drift leaves the array (fewer than 3 sources within their
    # half-detection range on more than 1 - this fraction of days) is drawn again. Where no
    # source can be heard the data cannot hold a track, whatever the tracker; 0 keeps every
    # float (the tracker then marks such stretches `unsupported`).
    min_covered_fraction: float = 0.9

    def __post_init__(self) -> None:
        shortest = self.gap_days[1] + 21  # a gap is placed at least 10 days from either end
        if self.gaps and self.days < shortest:
            raise ValueError(
                f"StressConfig: days must be at least {shortest} with gaps (got {self.days}); or gaps=False"
            )
        check_kinds(self.faults)
        clock_faults = sorted(set(self.faults) & set(CLOCK_KINDS))
        if clock_faults and self.clock_end_offset_s is None:
            raise ValueError(
                f"StressConfig: the clock faults ({', '.join(clock_faults)}) need clock_end_offset_s "
                "(a true clock that drifted)"
            )
