"""The `sphere` command: one subcommand per module in :mod:`sphere.commands`.

A subcommand module defines ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``.
Modules are found by name, so adding a subcommand never means editing this file.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import pkgutil
import sys

from sphere import __version__, commands


class _BrokenCommand:
    """Stands in for a subcommand whose module failed to load, so the other subcommands still work."""

    def __init__(self, name: str, error: BaseException):
        self.HELP = f"(unavailable: {type(error).__name__}: {error})"
        self._message = f"sphere {name}: this subcommand failed to load: {type(error).__name__}: {error}"

    def add_arguments(self, parser) -> None:
        parser.add_argument("rest", nargs=argparse.REMAINDER)

    def run(self, args) -> int:
        print(self._message, file=sys.stderr)
        print("reinstall with the README's setup command; if it persists, it is a bug: please report it", file=sys.stderr)
        return 1


def _command_modules():
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        name = info.name.replace("_", "-")
        try:
            yield name, importlib.import_module(f"sphere.commands.{info.name}")
        except Exception as e:  # one broken subcommand must not take the others down
            yield name, _BrokenCommand(name, e)


#: errors of a write that failed because of where the output goes (a full disk, /dev/full, a dead terminal)
OUTPUT_ERRNOS = (errno.ENOSPC, errno.EIO, errno.EFBIG, errno.EDQUOT, errno.EROFS)


def output_failed(prog: str, e: BaseException) -> int | None:
    """For an OSError of :data:`OUTPUT_ERRNOS`: one line on stderr and the exit status 1 (stdout is pointed at
    /dev/null, so that Python's final flush does not fail again); None for any other error."""
    if not isinstance(e, OSError) or e.errno not in OUTPUT_ERRNOS:
        return None
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    print(f"{prog}: cannot write the output: {e.strerror}; make room (or write it somewhere else)", file=sys.stderr)
    return 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sphere",
        description="Tools for the MARG sphere: decode and record its serial stream, evaluate fusion "
        "filters, run the simulated sphere, calibrate.",
    )
    parser.add_argument("--version", action="version", version=f"sphere {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in _command_modules():
        p = sub.add_parser(name, help=module.HELP, description=getattr(module, "DESCRIPTION", module.HELP))
        try:
            module.add_arguments(p)
        except Exception as e:
            module = _BrokenCommand(name, e)
            p = sub._name_parser_map[name] = argparse.ArgumentParser(prog=f"sphere {name}")
            module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("sphere: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # `sphere decode ... | head` closes the pipe early; that is not an error.
        sys.stderr.close()
        return 0
    except OSError as e:
        code = output_failed("sphere", e)
        if code is None:
            raise
        return code


if __name__ == "__main__":
    sys.exit(main())
