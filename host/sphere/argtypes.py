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
    """A file to write: not a folder, in a folder that exists, and one that can be created or written there
    (checked before any work is done, so a long run never ends in a file it cannot write)."""
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder: give a file name to write")
    parent = os.path.dirname(os.path.abspath(text))
    if not os.path.isdir(parent):
        raise argparse.ArgumentTypeError(f"{text!r}: the folder {parent} does not exist")
    _probe(text, lambda: os.close(os.open(text, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)), lambda: os.unlink(text))
    return text


PLOT_EXTRA = "it needs matplotlib, the plot extra: pip install 'marg-sphere[plot]'"


def image_file(text: str) -> str:
    """An image for matplotlib to write: :func:`out_file`, its name ending in a format matplotlib writes (.png,
    .svg, .pdf ...), and matplotlib installed, so a long run does not end in matplotlib's ValueError or an
    ImportError."""
    out_file(text)
    try:
        from matplotlib.backend_bases import FigureCanvasBase  # optional: matplotlib (the plot extra)
    except ImportError:
        raise argparse.ArgumentTypeError(f"{text!r}: {PLOT_EXTRA}") from None
    kinds = FigureCanvasBase.get_supported_filetypes()
    if os.path.splitext(text)[1].lstrip(".").lower() not in kinds:
        raise argparse.ArgumentTypeError(f"{text!r}: end the name in an image format matplotlib writes: "
                                         f"{', '.join('.' + k for k in sorted(kinds))}, e.g. .png")
    return text


def plot_dir(text: str) -> str:
    """A folder for matplotlib's plots: :func:`out_dir`, and matplotlib installed."""
    out_dir(text)
    try:
        import matplotlib  # noqa: F401  # optional: matplotlib (the plot extra)
    except ImportError:
        raise argparse.ArgumentTypeError(f"{text!r}: {PLOT_EXTRA}") from None
    return text


def out_dir(text: str) -> str:
    """A folder to write files into: an existing folder, or one that can be made (checked before any work)."""
    if os.path.exists(text) and not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a file: give a folder to write into")
    path = os.path.abspath(text)
    first_missing = None
    while not os.path.exists(path):  # the outermost folder that would be made
        first_missing, path = path, os.path.dirname(path)
    if not os.path.isdir(path):
        raise argparse.ArgumentTypeError(f"{text!r}: {path} is a file, not a folder")
    if first_missing is None:
        if not os.access(path, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{text!r} cannot be written: permission denied; give another folder")
        return text
    _probe(text, lambda: os.mkdir(first_missing), lambda: os.rmdir(first_missing))
    return text


def _probe(text: str, make, undo) -> None:
    """Try to create ``text`` (``make``) and take it away again (``undo``); an existing file is tried for
    writing only. A device or FIFO is left alone (/dev/full, /dev/null: the write itself tells)."""
    if os.path.exists(text):
        if os.path.isfile(text) and not os.access(text, os.W_OK):
            raise argparse.ArgumentTypeError(f"{text!r} cannot be written: permission denied; give another file")
        return
    try:
        make()
    except FileExistsError:  # made meanwhile by someone else: theirs to keep
        return
    except OSError as e:
        raise argparse.ArgumentTypeError(f"{text!r} cannot be written: {e.strerror or e}; give a path you can "
                                         "write to") from None
    try:
        undo()
    except OSError:
        pass


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


def at_most(kind, limit: float, unit: str, why: str = ""):
    """An argparse type: ``kind`` (one of these checks), then at most ``limit`` (``unit`` and ``why`` for the line)."""

    def parse(text: str) -> float:
        v = kind(text)
        if v > limit:
            raise argparse.ArgumentTypeError(f"{text!r}: give at most {limit:g} {unit}{why}")
        return v

    return parse


#: the virtual webcam's distance to the ball, in metres: more than 0 and at most 10
distance_m = at_most(positive, 10.0, "m", " (farther, the 8 cm ball is under 5 px across in the 640x480, 60° view)")


def hue_deg(text: str) -> float:
    """A hue in degrees, 0 to 360."""
    return at_most(non_negative, 360.0, "degrees", " (a hue is 0 to 360)")(text)


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


def stretches(text: str) -> list[tuple[str, float]]:
    """Stretches of BROAD trials, ``TRIAL[:START_S],...``: [(trial, start s)], the start 40 s when not given."""
    out = []
    for item in text.split(","):
        name, sep, start = item.strip().partition(":")
        try:
            start_s = float(start) if sep else 40.0
            if not name or not (math.isfinite(start_s) and start_s >= 0):
                raise ValueError
        except ValueError:
            raise argparse.ArgumentTypeError(f"{item.strip()!r}: give TRIAL or TRIAL:START_S (seconds, 0 or more), "
                                             "comma-separated, e.g. 10:40,16:40") from None
        out.append((name, start_s))
    return out


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
