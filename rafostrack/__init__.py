"""rafostrack: track RAFOS floats from unlabelled, ranked arrival times.

`rafostrack.track(float_file, **options)` tracks one float (see `rafostrack.api`).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rafostrack")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"


def __getattr__(name: str):
    """`rafostrack.track` (the Python API, `rafostrack.api`), imported on first use so that
    `import rafostrack` stays light."""
    if name in ("track", "TrackRun"):
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'rafostrack' has no attribute {name!r}")
