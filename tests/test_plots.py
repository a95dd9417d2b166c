"""Plots: three valid PNGs written atomically, also for degenerate inputs."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rafostrack.config import load_config
from rafostrack.domain import BeaconTable, FloatInfo
from rafostrack.model.measurement import predicted_arrivals
from rafostrack.plots import beacon_colors, write_plots
from rafostrack.summaries.estimates import MODE_COLUMNS, Estimate

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
NAMES = ["track.png", "arrivals.png", "uncertainty.png"]
T0 = np.datetime64("2010-01-01T00:00:00", "ns")
NAT = np.datetime64("NaT", "ns")


@pytest.fixture(scope="module")
def model():
    return load_config().model


@pytest.fixture(scope="module")
def beacons() -> BeaconTable:
    return BeaconTable(
        beacon_id=np.array(["S1", "S2", "S3", "S4"], dtype=object),
        lat=np.array([-56.0, -60.0, -57.5, -61.0]),
        lon=np.array([-100.0, -98.0, -88.0, -86.0]),
        offset_s=np.zeros(4),
        drift_s_per_day=np.array([0.0, 0.01, 0.0, -0.02]),
        start=np.array([NAT, NAT, NAT, T0 + np.timedelta64(10, "D")]),
        end=np.array([NAT, NAT, NAT, NAT]),
    )


@pytest.fixture(scope="module")
def info() -> FloatInfo:
    return FloatInfo(
        float_id="F01",
        launch_time=T0,
        launch_lat=-58.0,
        launch_lon=-96.0,
        end_time=T0 + np.timedelta64(29, "D"),
        end_lat=-58.6,
        end_lon=-91.5,
        clock_offset_start_s=0.0,
        clock_offset_end_s=0.0,
        window_s=4200.0,
        max_signals=4,
    )


def make_track(n: int, *, sd: float | None = 5.0) -> pd.DataFrame:
    k = np.arange(n)
    return pd.DataFrame(
        {
            "float_id": "F01",
            "time": T0 + k * np.timedelta64(1, "D"),
            "lat": -58.0 - 0.02 * k,
            "lon": -96.0 + 0.15 * k,
            "sd_km": np.full(n, np.nan) if sd is None else sd + 0.3 * k,
            "ess": np.linspace(900.0, 300.0, n),
            "n_signals": (k % 5).astype(int),
            "loglik": -10.0 - k,
        }
    )


def make_labels(track: pd.DataFrame, beacons: BeaconTable, info: FloatInfo, model) -> pd.DataFrame:
    """One TOA per active beacon per window at the predicted time, plus one clutter TOA."""
    pred = predicted_arrivals(track.time.to_numpy(), track.lat.to_numpy(), track.lon.to_numpy(), beacons, info, model)
    rows = []
    for k, t in enumerate(track.time):
        toas = [(pred[k, j], beacons.beacon_id[j], 0.9) for j in range(len(beacons)) if np.isfinite(pred[k, j])]
        toas.append((100.0 + 37.0 * k, None, 0.6))
        for rank, (toa, bid, p) in enumerate(sorted(toas, key=lambda r: r[0]), start=1):
            rows.append(
                {
                    "float_id": "F01",
                    "time": t,
                    "rank": rank,
                    "toa_s": toa,
                    "beacon_id": bid,
                    "prob": p,
                    "p_clutter": p if bid is None else 1 - p,
                }
            )
    return pd.DataFrame(rows)


def empty_labels() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "float_id": pd.Series([], dtype=object),
            "time": pd.Series([], dtype="datetime64[ns]"),
            "rank": pd.Series([], dtype=int),
            "toa_s": pd.Series([], dtype=float),
            "beacon_id": pd.Series([], dtype=object),
            "prob": pd.Series([], dtype=float),
            "p_clutter": pd.Series([], dtype=float),
        }
    )


def assert_pngs(outdir: Path, paths: list[Path]) -> None:
    assert [p.name for p in paths] == NAMES
    for p in paths:
        assert p.parent == outdir and p.is_file()
        data = p.read_bytes()
        assert data[:8] == PNG_MAGIC
        assert len(data) > 10_000
        width, height = struct.unpack(">II", data[16:24])  # IHDR
        assert (width, height) == (1200, 720)
    assert sorted(f.name for f in outdir.iterdir()) == sorted(NAMES)  # no temporary files left


def _estimate(track: pd.DataFrame, labels: pd.DataFrame) -> Estimate:
    return Estimate("smoothed", track, labels, pd.DataFrame(columns=list(MODE_COLUMNS)))


def test_write_plots_full(tmp_path, beacons, info, model):
    track = make_track(30)
    labels = make_labels(track, beacons, info, model)
    truth = track[["time", "lat", "lon"]].assign(lat=track.lat + 0.05)
    paths = write_plots(tmp_path / "out", _estimate(track, labels), beacons, info, model, truth=truth)
    assert_pngs(tmp_path / "out", paths)


@pytest.mark.filterwarnings("error")
def test_write_plots_empty_labels(tmp_path, beacons, info, model):
    paths = write_plots(tmp_path, _estimate(make_track(30), empty_labels()), beacons, info, model)
    assert_pngs(tmp_path, paths)


@pytest.mark.filterwarnings("error")
def test_write_plots_single_window_all_clutter_nan_sd(tmp_path, beacons, info, model):
    track = make_track(1, sd=None)
    labels = make_labels(track, beacons, info, model).assign(beacon_id=None, prob=0.7)
    labels.loc[0, "beacon_id"] = np.nan  # clutter may also come back as NaN from a file
    paths = write_plots(tmp_path, _estimate(track, labels), beacons, info, model)
    assert_pngs(tmp_path, paths)


def test_write_plots_empty_track_overwrites(tmp_path, beacons, info, model):
    no_end = FloatInfo(**{**info.__dict__, "end_time": NAT, "end_lat": np.nan, "end_lon": np.nan})
    for name in NAMES:  # stale output from an earlier run is replaced
        (tmp_path / name).write_bytes(b"old")
    paths = write_plots(tmp_path, _estimate(make_track(0), empty_labels()), beacons, no_end, model)
    assert_pngs(tmp_path, paths)


def test_beacon_colors_distinct_and_not_grey():
    colors = beacon_colors([f"B{i}" for i in range(18)])
    rgb = {c[:3] for c in colors.values()}
    assert len(rgb) == 18
    assert all(not (r == g == b) for r, g, b in rgb)


# --------------------------------------------------------------------------------------
# The map and the other plots, read back from the drawn figure


def _capture(monkeypatch, module):
    """Replace `module.save_png` by one that draws the figure, keeps a snapshot, and saves."""
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Polygon
    from matplotlib.text import Annotation

    shots: list[dict] = []
    original = module.save_png

    def save(fig, path):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        ax = fig.axes[0]
        shot = {
            "title": ax.get_title(),
            "xlim": ax.get_xlim(),
            "ylim": ax.get_ylim(),
            "xticks": [t.get_text() for t in ax.get_xticklabels() if t.get_text()],
            "yticks": [t.get_text() for t in ax.get_yticklabels() if t.get_text()],
            "ellipses": [p for p in ax.patches if isinstance(p, Polygon)],
            "ellipse_px": [p.get_window_extent(renderer) for p in ax.patches if isinstance(p, Polygon)],
            "labels": [a for a in ax.texts if isinstance(a, Annotation)],
            "texts": [t.get_text() for t in ax.texts],
            "track_zorder": max(
                [a.get_zorder() for a in [*ax.lines, *ax.collections] if isinstance(a, Line2D | Collection)] or [0]
            ),
            "scalebar": [a for a in [*ax.lines, *ax.texts] if a.get_gid() == "scalebar"],
            "legends": [
                (lg, lg.get_window_extent(renderer)) for lg in [*fig.legends, *(a.get_legend() for a in fig.axes)] if lg
            ],
            "axes_px": [a.get_window_extent(renderer) for a in fig.axes],
            "cbar_ticks": [t.get_text() for a in fig.axes[1:] for t in a.get_yticklabels() if t.get_text()],
            "fig": fig,
        }
        shots.append(shot)
        return original(fig, path)

    monkeypatch.setattr(module, "save_png", save)
    return shots


def test_map_degree_labels_title_frame_and_scale_bar(tmp_path, monkeypatch, beacons, info):
    import rafostrack.plots.track_map as track_map

    shots = _capture(monkeypatch, track_map)
    named = FloatInfo(**{**info.__dict__, "float_id": "float767"})
    track = make_track(30).assign(float_id="float767")
    far = BeaconTable(**{**beacons.__dict__, "lat": beacons.lat * 1.0, "lon": beacons.lon - 20.0})  # far west
    track_map.plot_track(track, far, named, tmp_path / "track.png")
    shot = shots[-1]
    assert all(t.endswith("°W") for t in shot["xticks"]) and all(t.endswith("°S") for t in shot["yticks"])
    assert "Float float767" not in shot["title"] and shot["title"].startswith("float767")
    # The frame is the track's (plus a margin), not the beacons' (they are 20° further west).
    lon0, lon1 = shot["xlim"]
    assert lon0 > -100 and lon1 < -88 and lon0 < -96 and lon1 > -91.5
    assert shot["scalebar"] and any(t.endswith(" km") for t in shot["texts"])
    bar = next(a for a in shot["scalebar"] if hasattr(a, "get_xdata"))
    km = float(next(t for t in shot["texts"] if t.endswith(" km")).split()[0])
    x = bar.get_xdata()
    lat = float(np.mean(bar.get_ydata()))
    assert abs(x[1] - x[0]) * 111.2 * np.cos(np.radians(lat)) == pytest.approx(km, rel=0.01)


def test_map_ellipses_visible_with_a_matching_legend_patch(tmp_path, monkeypatch, beacons, info):
    import rafostrack.plots.track_map as track_map

    shots = _capture(monkeypatch, track_map)
    track = make_track(60, sd=0.3)  # sub-km uncertainty on a ~500 km track
    track = track.assign(lon=-96.0 + 0.12 * np.arange(60), smaj_km=0.4, smin_km=0.2, angle_deg=30.0)
    track_map.plot_track(track, beacons, info, tmp_path / "track.png")
    shot = shots[-1]
    assert shot["ellipses"]
    assert min(max(b.width, b.height) for b in shot["ellipse_px"]) >= 4.0  # visible on the PNG
    patch = next(h for lg, _ in shot["legends"] for h in lg.legend_handles if "95%" in (h.get_label() or ""))
    first = shot["ellipses"][0]
    assert patch.get_facecolor()[3] == pytest.approx(first.get_facecolor()[3])
    assert patch.get_edgecolor()[3] == pytest.approx(first.get_edgecolor()[3])
    assert patch.get_linewidth() == pytest.approx(first.get_linewidth())
    assert "enlarged" in patch.get_label()  # sub-km ellipses are drawn enlarged, and say so


def test_map_beacon_labels_above_the_track(tmp_path, monkeypatch, beacons, info):
    import rafostrack.plots.track_map as track_map

    shots = _capture(monkeypatch, track_map)
    track_map.plot_track(make_track(30), beacons, info, tmp_path / "track.png")
    shot = shots[-1]
    labels = [a for a in shot["labels"] if a.get_text() in {"S1", "S2", "S3", "S4"}]
    assert labels and min(a.get_zorder() for a in labels) > shot["track_zorder"]


@pytest.mark.parametrize(("days", "fmt"), [(14, "%d %b"), (700, "%b %Y")])
def test_map_date_colourbar_ticks(tmp_path, monkeypatch, beacons, info, days, fmt):
    import datetime as dt

    import rafostrack.plots.track_map as track_map

    shots = _capture(monkeypatch, track_map)
    track = make_track(days + 1)
    track_map.plot_track(track, beacons, info, tmp_path / "track.png")
    ticks = shots[-1]["cbar_ticks"]
    assert 3 <= len(ticks) <= 9 and len(set(ticks)) == len(ticks)
    for text in ticks:
        dt.datetime.strptime(text, fmt)  # every tick is a plain date


def test_map_background_seam_gets_the_frame(tmp_path, monkeypatch, beacons, info):
    import rafostrack.plots.track_map as track_map

    shots = _capture(monkeypatch, track_map)
    calls = []

    def background(ax, lat_min, lat_max, lon_min, lon_max):
        calls.append((lat_min, lat_max, lon_min, lon_max))
        ax.axhspan(lat_min, lat_max, color="0.9", zorder=0)

    track_map.plot_track(make_track(30), beacons, info, tmp_path / "track.png", background=background)
    ((lat_min, lat_max, lon_min, lon_max),) = calls
    assert (lon_min, lon_max) == pytest.approx(shots[-1]["xlim"]) and (lat_min, lat_max) == pytest.approx(
        shots[-1]["ylim"]
    )


def _srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    m = np.array(
        [[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750], [0.0193339, 0.1191920, 0.9503041]]
    )
    xyz = lin @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 216 / 24389, np.cbrt(xyz), (24389 / 27 * xyz + 16) / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1)


def _ciede2000(lab1: np.ndarray, lab2: np.ndarray) -> float:
    """CIEDE2000 colour difference (Sharma, Wu and Dalal 2005)."""
    (l1, a1, b1), (l2, a2, b2) = lab1, lab2
    cbar = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(cbar**7 / (cbar**7 + 25**7)))
    a1p, a2p = (1 + g) * a1, (1 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p, h2p = np.degrees(np.arctan2(b1, a1p)) % 360, np.degrees(np.arctan2(b2, a2p)) % 360
    dh = 0.0 if c1p * c2p == 0 else (h2p - h1p + 180) % 360 - 180
    dhp = 2 * np.sqrt(c1p * c2p) * np.sin(np.radians(dh / 2))
    lbp, cbp = (l1 + l2) / 2, (c1p + c2p) / 2
    if c1p * c2p == 0:
        hbp = h1p + h2p
    elif abs(h1p - h2p) <= 180:
        hbp = (h1p + h2p) / 2
    else:
        hbp = (h1p + h2p + (360 if h1p + h2p < 360 else -360)) / 2
    t = (1 - 0.17 * np.cos(np.radians(hbp - 30)) + 0.24 * np.cos(np.radians(2 * hbp))
         + 0.32 * np.cos(np.radians(3 * hbp + 6)) - 0.2 * np.cos(np.radians(4 * hbp - 63)))  # fmt: skip
    rc = 2 * np.sqrt(cbp**7 / (cbp**7 + 25**7))
    sl = 1 + 0.015 * (lbp - 50) ** 2 / np.sqrt(20 + (lbp - 50) ** 2)
    sc, sh = 1 + 0.045 * cbp, 1 + 0.015 * cbp * t
    rt = -np.sin(np.radians(60 * np.exp(-(((hbp - 275) / 25) ** 2)))) * rc
    dl, dc = (l2 - l1) / sl, (c2p - c1p) / sc
    return float(np.sqrt(dl**2 + dc**2 + (dhp / sh) ** 2 + rt * dc * (dhp / sh)))


def test_ciede2000_oracle_matches_published_pairs():
    # Sharma, Wu and Dalal (2005), table 1, pairs 1 and 17.
    assert _ciede2000(np.array([50.0, 2.6772, -79.7751]), np.array([50.0, 0.0, -82.7485])) == pytest.approx(
        2.0425, abs=1e-4
    )
    assert _ciede2000(np.array([50.0, 2.5, 0.0]), np.array([73.0, 25.0, -18.0])) == pytest.approx(27.1492, abs=1e-4)


def test_twenty_beacon_colours_are_told_apart():
    """Beacons sharing tab20's light/dark pairs were hard to tell apart. Every
    two of the first 20 beacon colours, and each against the clutter grey and the white
    background, differ by at least 20 CIEDE2000 units (tab20's own pairs: 12)."""
    from matplotlib.colors import to_rgb

    from rafostrack.plots.base import CLUTTER_COLOR

    colors = beacon_colors([f"B{i}" for i in range(20)])
    labs = [_srgb_to_lab(np.array(c[:3])) for c in colors.values()]
    refs = [_srgb_to_lab(np.array(to_rgb(CLUTTER_COLOR))), _srgb_to_lab(np.ones(3))]
    pairs = [_ciede2000(a, b) for i, a in enumerate(labs) for b in labs[i + 1 :]]
    assert min(pairs) >= 20.0
    assert min(_ciede2000(a, r) for a in labs for r in refs) >= 20.0


def test_uncertainty_legend_off_the_data(tmp_path, monkeypatch):
    import rafostrack.plots.uncertainty as uncertainty

    shots = _capture(monkeypatch, uncertainty)
    track = make_track(40).assign(ambiguous=np.arange(40) % 10 < 3)
    uncertainty.plot_uncertainty(track, tmp_path / "u.png")
    shot = shots[-1]
    assert shot["legends"]
    for _, box in shot["legends"]:
        assert not any(box.overlaps(ax) for ax in shot["axes_px"])


def test_map_title_is_inside_the_figure_and_beacon_labels_do_not_overlap(info):
    """Five sources far east of the track, their edge markers almost on one another (as
    UK1-2 and UK1-4 on float767's map, where one label hid the other), and a wide frame:
    every label is drawn apart, and the title is not cut off at the top."""
    from rafostrack.plots import track_map
    from rafostrack.plots.base import figure

    n = 6
    crowd = BeaconTable(
        beacon_id=np.array([f"UK1-{k}" for k in range(1, n + 1)], dtype=object),
        lat=-58.3 + 0.08 * np.arange(n),
        lon=np.full(n, -70.0),
        offset_s=np.zeros(n),
        drift_s_per_day=np.zeros(n),
        start=np.full(n, NAT),
        end=np.full(n, NAT),
    )
    with figure() as fig:
        track_map.draw_track(fig, make_track(30), crowd, info)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        ax = fig.axes[0]
        boxes = [t.get_window_extent(renderer) for t in ax.texts if t.get_text().startswith("UK1-")]
        assert len(boxes) == n
        assert not [(i, j) for i in range(n) for j in range(i + 1, n) if boxes[i].overlaps(boxes[j])]
        assert ax.title.get_window_extent(renderer).y1 <= fig.bbox.height


@pytest.mark.parametrize("days", [5, 30])
def test_map_labels_of_sources_on_the_top_edge_stay_off_the_title(info, days):
    """Sources north of the float are pinned to the map's top edge (as on a synthetic mission's
    float with its sources north of it): their labels, and that of a source inside the frame
    just below its top, stay inside the map and never overlap the title."""
    from rafostrack.plots import track_map
    from rafostrack.plots.base import figure

    track = make_track(days)
    north = BeaconTable(
        beacon_id=np.array(["N1", "N2", "N3", "N4", "E1", "IN"], dtype=object),
        lat=np.array([-53.0, -52.5, -54.0, -50.0, -58.0, float(track.lat.max()) + 0.05]),
        lon=np.array([-97.0, -94.0, -90.0, -95.5, -60.0, float(track.lon.mean())]),
        offset_s=np.zeros(6),
        drift_s_per_day=np.zeros(6),
        start=np.full(6, NAT),
        end=np.full(6, NAT),
    )
    with figure() as fig:
        track_map.draw_track(fig, track, north, info)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        ax = fig.axes[0]
        title, frame = ax.title.get_window_extent(renderer), ax.get_window_extent(renderer)
        labels = [t for t in ax.texts if t.get_text() in set(north.beacon_id)]
        assert len(labels) == len(north)
        for text in labels:
            box = text.get_window_extent(renderer)
            assert not box.overlaps(title), text.get_text()
            assert frame.y0 <= box.y0 and box.y1 <= frame.y1 and frame.x0 <= box.x0 and box.x1 <= frame.x1


def test_arrivals_leave_out_a_beacon_never_heard(beacons, info, model):
    """S2's predicted arrivals lie inside the window, but none of the float's TOAs is labelled
    to it: no curve and no legend entry for it, and the legend's title says it was not heard."""
    from matplotlib.colors import to_rgba

    from rafostrack.plots.arrivals import draw_arrivals
    from rafostrack.plots.base import figure

    track = make_track(30)
    labels = make_labels(track, beacons, info, model)
    labels = labels[labels.beacon_id != "S2"]
    pred = predicted_arrivals(track.time.to_numpy(), track.lat.to_numpy(), track.lon.to_numpy(), beacons, info, model)
    assert ((pred[:, 1] > 0) & (pred[:, 1] < info.window_s)).all()  # S2 would be drawn in the window
    s2 = to_rgba(beacon_colors(["S1", "S2", "S3", "S4"])["S2"])
    with figure() as fig:
        draw_arrivals(fig, labels, track, beacons, info, model)
        ax, legend = fig.axes[0], fig.legends[0]
        entries = [t.get_text() for t in legend.get_texts()]
        assert not [e for e in entries if e.startswith("S2")]
        assert {"S1 (30)", "S3 (30)"} <= set(entries)
        assert not [line for line in ax.lines if to_rgba(line.get_color())[:3] == s2[:3]]
        assert "not heard: S2" in legend.get_title().get_text()


@pytest.mark.parametrize(("days", "span"), [(20, "Jan 2010"), (700, "Jan 2010 – Dec 2011")])
def test_time_axes_are_labelled_with_the_year(beacons, info, model, days, span):
    """The arrivals and uncertainty plots' time axes say what they are, and the months and
    years of the data (not of the padding before its first day)."""
    from rafostrack.plots.arrivals import draw_arrivals
    from rafostrack.plots.base import figure
    from rafostrack.plots.uncertainty import draw_uncertainty

    track = make_track(days)
    labels = make_labels(track, beacons, info, model)
    for draw, args in ((draw_arrivals, (labels, track, beacons, info, model)), (draw_uncertainty, (track,))):
        with figure() as fig:
            draw(fig, *args)
            fig.canvas.draw()
            label = fig.axes[len(fig.axes) - 1 if draw is draw_uncertainty else 0].get_xlabel()
            assert label == f"time (UTC), {span}"


def test_array_residuals_dates_once_per_column_under_its_lowest_panel(tmp_path, monkeypatch):
    """array.png with 5 source panels on 4 columns: the date ticks and the time label (with
    the months and years spanned) only under each column's lowest drawn panel, no offset
    text (a year) on any panel, and none under the panel that has one below it."""
    import rafostrack.plots.array_residuals as array_residuals

    drawn = {}

    def save(fig, path):  # what each drawn panel shows (the figure is cleared after)
        fig.canvas.draw()
        drawn["axes"] = [
            {
                "title": a.get_title(),
                "ticks": [t.get_text() for t in a.get_xticklabels() if t.get_visible() and t.get_text()],
                "offset": a.xaxis.get_offset_text().get_text(),
                "label": a.get_xlabel(),
            }
            for a in fig.axes
            if a.get_visible()
        ]
        return path

    monkeypatch.setattr(array_residuals, "save_png", save)
    time = np.datetime64("2010-03-01") + np.arange(0, 400, 10).astype("timedelta64[D]")
    zeros = np.zeros(len(time))
    panels = [
        array_residuals.SourcePanel(f"S{k}", time, np.zeros(len(time), dtype=np.intp), zeros + k, zeros)
        for k in range(5)
    ]
    array_residuals.plot_array_residuals(tmp_path / "array.png", panels, ["f1"])
    axes = drawn["axes"]
    assert [a["title"] for a in axes] == [f"S{k}" for k in range(5)]
    assert [a["title"] for a in axes if a["ticks"]] == ["S1", "S2", "S3", "S4"]  # S0 has S4 below it
    for a in axes:
        assert a["offset"] == ""
        assert a["label"] == ("time (UTC), Mar 2010 – Mar 2011" if a["ticks"] else "")
