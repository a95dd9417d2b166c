"""rafostrack: track RAFOS floats from unlabelled, ranked arrival times.

`rafostrack.track(float_file, **options)` tracks one float (see `rafostrack.api`);
`rafostrack.sample_path()` is the sample mission installed with the package.
"""

from importlib import resources
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

try:
    __version__ = version("rafostrack")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"


def sample_path(name: str = "") -> Path:
    """The sample mission installed with the package (a copy of the repository's data/samples:
    DIMES geometry, SIMULATED arrivals), or its file `name`, e.g. `sample_path("float811.csv")`."""
    folder = Path(str(resources.files("rafostrack").joinpath("data", "samples")))
    return folder / name if name else folder


def __getattr__(name: str):
    """`rafostrack.track` (the Python API, `rafostrack.api`), imported on first use so that
    `import rafostrack` stays light."""
    if name in ("track", "TrackRun"):
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'rafostrack' has no attribute {name!r}")
