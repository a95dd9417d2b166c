"""How the command line reports a mistake: one line `rafostrack: error: ...` and exit code 2
for a user's (`InputError`, an unwritable output path, a bad option), 1 for a bug; the
traceback or click's usage text with `--debug`."""

from __future__ import annotations

import sys
from functools import wraps
from pathlib import Path

import click

from ..errors import InputError


def report_errors(func):
    """Turn errors into one line on stderr, no traceback (unless `--debug`): user-facing
    errors (`InputError`, an unwritable output path) exit with code 2, unexpected ones with 1.
    An `out_dir` argument is checked before any work."""

    @wraps(func)
    def wrapper(*args, **kwargs):
        from ..io.outdir import check_output_dir

        debug = _debug(click.get_current_context())
        out_dir = kwargs.get("out_dir")
        try:
            if out_dir is not None:
                check_output_dir(out_dir)
            return func(*args, **kwargs)
        except InputError as exc:
            if debug:
                raise
            click.echo(f"rafostrack: error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # e.g. output directory not writable, disk full
            if debug:
                raise
            name = Path(exc.filename) if exc.filename else None
            where, expected = (f"{name}: " if name else ""), ""
            if out_dir is not None and name is not None and (name == Path(out_dir) or Path(out_dir) in name.parents):
                where = f"cannot write output directory {out_dir}: {where}"
                expected = "; expected a writable directory with room to write"
            reason = " ".join(str(exc.strerror or exc).splitlines())
            click.echo(f"rafostrack: error: {where}{reason}{expected}", err=True)
            sys.exit(2)
        except (click.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except Exception as exc:  # a bug, not a user mistake: still one line unless --debug
            if debug:
                raise
            reason = " ".join(str(exc).splitlines()) or "no message"
            click.echo(
                f"rafostrack: internal error: {type(exc).__name__}: {reason} (rerun with --debug for the traceback)",
                err=True,
            )
            sys.exit(1)

    return wrapper


def _debug(ctx: click.Context) -> bool:
    """Whether `--debug` was given, before or after the subcommand."""
    return bool(ctx.find_root().params.get("debug", False) or ctx.meta.get("rafostrack.debug", False))


def _set_debug(ctx: click.Context, _param: click.Parameter, value: bool) -> bool:
    if value:
        ctx.meta["rafostrack.debug"] = True
    return value


def debug_option(func):
    """`--debug` on a subcommand too (`rafostrack track F --debug`), as on the root."""
    return click.option(
        "--debug",
        is_flag=True,
        expose_value=False,
        callback=_set_debug,
        help="Show tracebacks instead of one-line errors.",
    )(func)


class RafostrackGroup(click.Group):
    """The root command. A usage error (a bad option value, an unknown option or command, a
    missing argument) prints the documented one line `rafostrack: error: ...` and exits
    with code 2, like every other user mistake; with `--debug`, click's full usage text."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):  # type: ignore[override]
        argv = list(sys.argv[1:] if args is None else args)
        try:
            rv = super().main(argv, "rafostrack", complete_var, standalone_mode=False, **extra)
        except click.ClickException as exc:
            if "--debug" in argv:
                exc.show()
            else:
                click.echo(f"rafostrack: error: {_usage_message(exc)}", err=True)
            sys.exit(exc.exit_code)
        except click.exceptions.Abort:
            click.echo("rafostrack: aborted", err=True)
            sys.exit(1)
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


def _usage_message(exc: click.ClickException) -> str:
    """One line: the command, click's message, and where to find the usage."""
    message = " ".join(exc.format_message().split())
    ctx = getattr(exc, "ctx", None)
    if ctx is None:
        return message
    path = ctx.command_path
    where = "" if ctx.parent is None else f"{path.split(' ', 1)[-1]}: "
    return f"{where}{message} (see '{path} --help')"
