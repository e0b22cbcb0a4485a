"""The ``raingauge`` command line.

Each subcommand lives in its own module under :mod:`raingauge.commands` (or
:mod:`calibration` for ``calibrate``) and provides two functions::

    def add_arguments(parser: argparse.ArgumentParser) -> None: ...
    def run(args: argparse.Namespace) -> int: ...

plus a module docstring whose first line is the one-line help.  Heavy imports
(OpenCV, pymodbus) belong inside ``run`` so that ``raingauge --help`` is fast.

Errors derived from :class:`raingauge.errors.RaingaugeError` are printed as
``raingauge: error: ...`` without a traceback, exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from raingauge import __version__
from raingauge.errors import RaingaugeError

#: subcommand -> module that implements it
COMMANDS: dict[str, str] = {
    "run": "raingauge.commands.run",
    "simulate": "raingauge.commands.simulate",
    "measure": "raingauge.commands.measure",
    "derain": "raingauge.commands.derain",
    "advise": "raingauge.commands.advise",
    "visibility": "raingauge.commands.visibility",
    "calibrate": "calibration.wizard",
    "dsd": "raingauge.commands.dsd",
    "export": "raingauge.commands.export",
    "plot": "raingauge.commands.plot",
    "drop-view": "raingauge.commands.drop_view",
    "render-streak": "raingauge.commands.render_streak",
    "profile": "raingauge.commands.profile",
}


def _load(name: str):
    try:
        return importlib.import_module(COMMANDS[name])
    except ModuleNotFoundError as exc:
        if exc.name == COMMANDS[name]:
            return None
        raise


class _Parser(argparse.ArgumentParser):
    """argparse with the command line's error format, ``raingauge: error: ...`` (exit status 2)."""

    def error(self, message: str):
        self.print_usage(sys.stderr)
        self.exit(2, f"raingauge: error: {message}. Fix: see '{self.prog} --help'\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = _Parser(
        prog="raingauge",
        description="A camera rain gauge: measure, remove and simulate rain in video.",
    )
    parser.add_argument("--version", action="version", version=f"raingauge {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if only is not None and name != only:
            # Still list the command in --help without importing it.
            sub.add_parser(name, add_help=False)
            continue
        module = _load(name)
        if module is None:
            continue
        doc = (module.__doc__ or "").strip().splitlines()
        help_line = doc[0] if doc else ""
        p = sub.add_parser(name, help=help_line, description=(module.__doc__ or "").strip(),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    only = argv[0] if argv and argv[0] in COMMANDS else None
    parser = build_parser(only)
    args = parser.parse_args(argv)
    if getattr(args, "_module", None) is None:
        parser.print_help()
        return 0 if not argv else 2
    try:
        return int(args._module.run(args) or 0)
    except RaingaugeError as exc:
        print(f"raingauge: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("raingauge: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
