"""rafostrack: track RAFOS floats from unlabelled, ranked arrival times."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rafostrack")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"
