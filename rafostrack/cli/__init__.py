"""Command-line interface: `rafostrack track`, `legs`, `batch`, `summary`, `simulate` and `config`.

Thin: parse options, call the pipeline, report (`commands`; the options they share in
`options`, how a mistake is reported in `errors`). A user mistake (`InputError`) prints one
line `rafostrack: error: ...` and exits with code 2; `--debug` shows the traceback.
"""

from __future__ import annotations

from .commands import main

__all__ = ["main"]
