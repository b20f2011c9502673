"""The ``mbicp-viz`` command line: thin glue, one module per command group.

Each module imports only typer and light modules at the top; the heavy ones (the matchers'
kernels, scipy, rerun, viser, matplotlib) load inside the commands that use them, so that
``--help`` answers at once.
"""

from __future__ import annotations

import sys

import typer
from typer.core import TyperGroup

from . import bench, evaluate, files, lesson, live, match, serve, tune


class OneLineErrors(TyperGroup):
    """Usage errors (a wrong choice, a missing argument) as one line and exit code 2, like every
    other error of the tool, instead of typer's boxed panels."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except typer.TyperException as e:
            if not hasattr(e, "format_message"):
                raise
            text = " ".join(e.format_message().split()).replace("Value error, ", "").rstrip(".")
            where = (
                f"; see: {e.ctx.command_path} --help" if getattr(e, "ctx", None) is not None else ""
            )
            typer.echo(f"mbicp-viz: error: {text}{where}", err=True)
            code = getattr(e, "exit_code", 2)
        except typer.Abort:
            typer.echo("mbicp-viz: aborted", err=True)
            code = 1
        if not standalone_mode:
            return code
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(
    cls=OneLineErrors,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="Visual debugger and teaching tool for 2-D laser scan matching (ICP, PL-ICP, MbICP, "
    "improved "
    "MbICP, PSM, PMWN).",
)
for group in (match, serve, live, lesson, evaluate, bench, files, tune):
    group.register(app)


def main() -> None:
    app()
