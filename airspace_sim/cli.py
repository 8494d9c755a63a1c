"""The ``airspace-sim`` command line.

Each subcommand is a module in :mod:`airspace_sim.commands` (``bench_world.py`` gives
``bench-world``) exposing ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Modules import their heavy dependencies
inside ``run`` so that ``airspace-sim --help`` stays fast.

A :class:`~airspace_sim.errors.UserError` raised anywhere becomes one line on stderr and
exit status 2, with no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from airspace_sim.errors import UserError

# Order in which subcommands are listed by --help; any other module found is appended.
_ORDER = ["run", "sweep", "risk", "encounters", "figures", "bench"]


def _command_modules() -> dict:
    import airspace_sim.commands as pkg

    names = [m.name for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_")]
    names.sort(key=lambda n: (_ORDER.index(n) if n in _ORDER else len(_ORDER), n))
    return {n: importlib.import_module(f"airspace_sim.commands.{n}") for n in names}


class _Parser(argparse.ArgumentParser):
    """An argparse parser whose errors are one line (what, the option, the value) and a
    pointer to ``--help``, not the usage block: the same shape as every other error."""

    def error(self, message: str):
        from airspace_sim.errors import escape

        self.exit(2, f"{self.prog}: error: {escape(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from airspace_sim import __version__

    parser = _Parser(
        prog="airspace-sim",
        description="2D multi-aircraft airspace simulator with IMM tracking and "
        "conflict detection and avoidance.",
    )
    parser.add_argument("--version", action="version", version=f"airspace-sim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, mod in _command_modules().items():
        # module bench_world.py -> subcommand "bench-world"
        p = sub.add_parser(name.replace("_", "-"), help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # a one-line usage error (2), or --help / --version (0)
        return exc.code if isinstance(exc.code, int) else 0
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0
    try:
        return int(args._run(args) or 0)
    except UserError as exc:
        print(f"airspace-sim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM where a command catches it
        status = getattr(exc, "exit_status", 130)
        what = "terminated" if status == 143 else "interrupted"
        print(f"airspace-sim {args.command}: {what}", file=sys.stderr)
        return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
