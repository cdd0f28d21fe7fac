"""argparse types for the commands' flags: a bad value is one clear line (argparse's usage error, exit 2),
never a traceback or a run that cannot end."""

from __future__ import annotations

import argparse
import math
import os

from sphere.link.port import check_baud


def seconds(text: str, max_s: float = math.inf) -> float:
    """A finite number of seconds greater than 0 (and at most ``max_s``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(v) or not 0 < v <= max_s:
        limit = f" and at most {max_s:g}" if math.isfinite(max_s) else ""
        raise argparse.ArgumentTypeError(f"{text!r}: give a number of seconds greater than 0{limit}")
    return v


def seconds_up_to(max_s: float):
    """:func:`seconds` with an upper limit, as an argparse type."""
    return lambda text: seconds(text, max_s)


def out_file(text: str) -> str:
    """A file to write: not a folder, in a folder that exists (checked before any work is done)."""
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder: give a file name to write")
    parent = os.path.dirname(os.path.abspath(text))
    if not os.path.isdir(parent):
        raise argparse.ArgumentTypeError(f"{text!r}: the folder {parent} does not exist")
    return text


def positive(text: str, least: float = 0.0, inclusive: bool = False) -> float:
    """A finite number greater than 0 (or than ``least``; ``inclusive``: at least ``least``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v) or v < least or (v == least and not inclusive):
        raise argparse.ArgumentTypeError(f"{text!r}: give a number {'of at least' if inclusive else 'greater than'} "
                                         f"{least:g}")
    return v


def non_negative(text: str) -> float:
    """A finite number, 0 or more (a moment, a length, a rate)."""
    return positive(text, 0.0, inclusive=True)


def count(text: str, least: int = 0) -> int:
    """A whole number of at least ``least`` (0 by default)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if v < least:
        raise argparse.ArgumentTypeError(f"{text!r}: give a whole number of at least {least}")
    return v


def at_least_one(text: str) -> int:
    """:func:`count` of at least 1."""
    return count(text, 1)


def baud(text: str) -> int:
    """A serial baud rate (50 … 4,000,000)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a baud rate (the sphere uses 115200)") from None
    problem = check_baud(v)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return v


def in_file(text: str) -> str:
    """A file to read: it exists and is not a folder."""
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder: give a file")
    if not os.path.exists(text):
        raise argparse.ArgumentTypeError(f"{text!r}: no such file")
    return text


def names_of(choices, what: str):
    """An argparse type for a comma-separated list of names out of ``choices`` (a collection, or a function giving
    one, called when the flag is parsed); ``what`` names one of them in the error line."""

    def parse(text: str) -> list[str]:
        known = list(choices() if callable(choices) else choices)
        names = [s.strip() for s in text.split(",") if s.strip()]
        bad = [s for s in names if s not in known]
        if bad or not names:
            raise argparse.ArgumentTypeError(f"{','.join(bad) or text!r}: not a {what}; the {what}s are "
                                             + ", ".join(known))
        return names

    return parse
