"""The `sphere` command: one subcommand per module in :mod:`sphere.commands`.

A subcommand module defines ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``.
Modules are found by name, so adding a subcommand never means editing this file.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import pkgutil
import sys
from pathlib import Path

from sphere import __version__, commands
from sphere.errors import output_failed


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


def _command_names() -> dict[str, str]:
    """Subcommand name → module name, for every module of :mod:`sphere.commands`."""
    return {info.name.replace("_", "-"): info.name
            for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda i: i.name)
            if not info.name.startswith("_")}


def _load(name: str, module_name: str):
    try:
        return importlib.import_module(f"sphere.commands.{module_name}")
    except Exception as e:  # one broken subcommand must not take the others down
        return _BrokenCommand(name, e)


def _help_of(module_name: str) -> str | None:
    """A subcommand's ``HELP`` read from its source, without importing it (the listing of ``sphere --help``
    then loads no subcommand's dependencies); None when it is not a plain string there."""
    try:
        source = Path(commands.__path__[0], f"{module_name}.py").read_text(encoding="utf-8")
        for node in ast.parse(source).body:
            if (isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == ["HELP"]
                    and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)):
                return node.value.value
    except (OSError, SyntaxError, UnicodeDecodeError):
        pass
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand; only ``command``'s module is imported and given its arguments (the
    others are listed with their ``HELP``), so a subcommand starts without loading the others. With no
    ``command`` every module is loaded."""
    parser = argparse.ArgumentParser(
        prog="sphere",
        description="Tools for the MARG sphere: decode and record its serial stream, evaluate fusion "
        "filters, run the simulated sphere, calibrate.",
    )
    parser.add_argument("--version", action="version", version=f"sphere {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in _command_names().items():
        help_text = _help_of(module_name) if command is not None and name != command else None
        if help_text is not None:
            sub.add_parser(name, help=help_text, description=help_text)
            continue
        module = _load(name, module_name)
        p = sub.add_parser(name, help=module.HELP, description=getattr(module, "DESCRIPTION", module.HELP))
        try:
            module.add_arguments(p)
        except Exception as e:
            module = _BrokenCommand(name, e)
            p = sub._name_parser_map[name] = argparse.ArgumentParser(prog=f"sphere {name}")
            module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def _command_in(argv: list[str]) -> str:
    """The subcommand ``argv`` names (its first word that is not an option), or "" for none."""
    return next((a for a in argv if not a.startswith("-")), "")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_in(argv))
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
