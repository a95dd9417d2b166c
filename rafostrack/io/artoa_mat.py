"""DIMES / ARTOA interim MATLAB files (`*.itm`, `rf*toa.mat`): a float's arrival times.

Variables (MATLAB v5/v7 read with scipy.io, v7.3 = HDF5 with h5py): `TOA` (s after the
window opens), `TOA_SEL` (1-based index into `SOSOREF` of the source a TOA was assigned to;
0 = unassigned, our clutter), `TOA_DATE` (the window's RAFOS day: Julian day - 2440000,
fractional) and `SOSOREF` (the source names, which must be beacon ids of the beacon table).
Either one entry per TOA (vectors of one length; a NaN TOA = a window that stored nothing)
or one row per window (TOA and TOA_SEL n x k, TOA_DATE n long; NaN = empty slot). Anything
else is refused with the shapes found: no other layout is publicly documented. The float id
is the file's stem; for `rf<number>toa.mat` the number (matched to floats.csv by number,
so `rf0767toa.mat` finds `float767`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..errors import InputError, Warnings, nearest
from .csv_table import require_file
from .output_formats import RAFOS_DAY_EPOCH
from .records import build_record

REQUIRED = ("TOA", "TOA_SEL", "TOA_DATE", "SOSOREF")
_RF = re.compile(r"^rf(?P<number>\d+)toa\.mat$", re.IGNORECASE)


def matches(path: Path) -> bool:
    name = Path(path).name
    return Path(path).suffix.lower() == ".itm" or bool(_RF.match(name))


def float_id(path: Path) -> str:
    m = _RF.match(Path(path).name)
    return str(int(m.group("number"))) if m else Path(path).stem


def _names(value: Any) -> list[str]:
    """SOSOREF as a list of names: a cell array, a char matrix (one name per row) or a string."""
    arr = np.asarray(value, dtype=object)
    if arr.dtype.kind in "US" or isinstance(value, str):
        return [str(s).strip() for s in np.atleast_1d(np.asarray(value)).ravel()]
    out = []
    for item in arr.ravel():
        item = np.asarray(item)
        out.append(str(item.ravel()[0]).strip() if item.size else "")
    return out


def _load_v5(path: Path) -> dict[str, Any]:
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        data = loadmat(path, squeeze_me=False, chars_as_strings=True)
    except (MatReadError, ValueError, TypeError, OSError, NotImplementedError) as exc:
        raise InputError(f"{path}: cannot read as a MATLAB file ({' '.join(str(exc).split())})") from None
    return {k: v for k, v in data.items() if not k.startswith("__")}


def _load_v73(path: Path) -> dict[str, Any]:
    """A MATLAB v7.3 (HDF5) file: arrays are stored transposed, char arrays as uint16 codes,
    cell arrays as object references."""
    import h5py

    out: dict[str, Any] = {}
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"{path}: cannot read as a MATLAB v7.3 (HDF5) file ({' '.join(str(exc).split())})") from None
    with f:
        for name in REQUIRED:
            if name not in f:
                continue
            ds = f[name]
            cls = ds.attrs.get("MATLAB_class", b"")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            if cls == "cell":
                out[name] = [_h5_text(f[ref]) for ref in np.asarray(ds[()]).T.ravel()]
            elif cls == "char":
                out[name] = [_chars(row) for row in np.asarray(ds[()]).T]
            else:
                out[name] = np.asarray(ds[()]).T
    return out


def _chars(codes: np.ndarray) -> str:
    return "".join(chr(int(c)) for c in np.asarray(codes).ravel() if int(c)).strip()


def _h5_text(ds: Any) -> str:
    return _chars(np.asarray(ds[()]))


def read_arrivals(path: Path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings) -> ArrivalRecord:
    """The float's windows from an interim MATLAB file (module docstring)."""
    import h5py

    path = Path(path)
    require_file(path, "expected an ARTOA interim MATLAB file")
    if path.stat().st_size == 0:
        raise InputError(
            f"{path}: file is empty (0 bytes); expected an ARTOA interim MATLAB file with {', '.join(REQUIRED)}"
        )
    data = _load_v73(path) if h5py.is_hdf5(path) else _load_v5(path)
    missing = [v for v in REQUIRED if v not in data]
    if missing:
        raise InputError(f"{path}: missing variable(s) {', '.join(missing)}; expected {', '.join(REQUIRED)}")
    toa = np.asarray(data["TOA"], dtype=float)
    sel = np.asarray(data["TOA_SEL"], dtype=float)
    day = np.asarray(data["TOA_DATE"], dtype=float)
    names = _names(data["SOSOREF"])
    if toa.shape != sel.shape:
        raise InputError(f"{path}: TOA {toa.shape} and TOA_SEL {sel.shape} differ in shape; expected the same")
    vectors = toa.ndim == 1 or 1 in toa.shape
    if vectors and day.size == toa.size:
        toa, sel, day = toa.ravel(), sel.ravel(), day.ravel()
    elif toa.ndim == 2 and day.size == toa.shape[0] and (day.ndim == 1 or 1 in day.shape):
        # one row per window; a row whose slots are all empty stored nothing: keep one entry for it
        first_slot = np.zeros(toa.shape, dtype=bool)
        first_slot[:, 0] = True
        keep = (np.isfinite(toa) | (first_slot & ~np.isfinite(toa).any(axis=1)[:, None])).ravel()
        day = np.repeat(day.ravel(), toa.shape[1])[keep]
        toa, sel = toa.ravel()[keep], sel.ravel()[keep]
    else:
        raise InputError(
            f"{path}: shapes TOA {np.shape(data['TOA'])}, TOA_DATE {np.shape(data['TOA_DATE'])}; expected vectors of "
            "one length (one entry per TOA) or TOA n x k with TOA_DATE n long (one row per window)"
        )
    if not np.isfinite(day).all():
        raise InputError(
            f"{path}: TOA_DATE entry {int(np.argmax(~np.isfinite(day))) + 1} is empty; expected a RAFOS day"
        )
    bad = np.isfinite(sel) & ((sel < 0) | (sel > len(names)) | (sel != np.round(sel)))
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(
            f"{path}: TOA_SEL entry {i + 1} = {sel[i]:g}; expected 0 (unassigned) or a source number 1..{len(names)}"
        )
    known = [str(b) for b in beacons.beacon_id]
    for name in names:
        if name not in known:
            hint = nearest(name, known) or f" (the beacon table has {', '.join(known)})"
            raise InputError(f"{path}: SOSOREF source {name!r} is not in the beacon table{hint}")
    labels = np.array([names[int(s) - 1] if np.isfinite(s) and s > 0 else None for s in sel], dtype=object)
    ns = np.round((day * 86400.0) * 1e3).astype(np.int64) * np.timedelta64(1, "ms")
    times = (RAFOS_DAY_EPOCH + ns).astype("datetime64[ns]")
    return build_record(path, info, beacons, times, toa, warnings, labels=labels, where=lambda i: f"TOA entry {i + 1}")
