"""Progress for commands that run longer than a few seconds: tqdm, the one choice for the whole CLI.

    from sphere.progress import bar, follow_capture
    for trial in bar(trials, desc="eval", unit="trial"):   # a bar over an iterable
        ...
    with follow_capture(path, seconds, desc="sim"):          # simulated seconds, read from a growing capture
        run_board(...)

Bars go to stderr and only when stderr is a terminal (``SPHERE_PROGRESS=1`` forces them, ``0`` turns them
off), so pipes, logs and tests see the figures alone.
"""

from __future__ import annotations

import os
import sys
import threading
from contextlib import contextmanager
from pathlib import Path

from tqdm import tqdm

from sphere.protocol import FrameDecoder, TimeUnwrapper


def enabled() -> bool:
    force = os.environ.get("SPHERE_PROGRESS")
    if force is not None:
        return force not in ("", "0")
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def bar(iterable=None, total=None, desc: str = "", unit: str = "it", **kw) -> tqdm:
    """A tqdm bar on stderr (disabled unless :func:`enabled`)."""
    return tqdm(iterable, total=total, desc=desc, unit=unit, file=sys.stderr, disable=not enabled(),
                dynamic_ncols=True, leave=False, **kw)


@contextmanager
def follow_capture(path, seconds: float, desc: str = "", poll_s: float = 0.25):
    """While the block runs, show how many device seconds the capture at ``path`` holds (of ``seconds``)."""
    if not enabled() or path is None:
        yield
        return

    done = threading.Event()

    def follow():
        decoder, unwrap, first, offset = FrameDecoder("device"), TimeUnwrapper(), None, 0
        with bar(total=round(seconds, 1), desc=desc, unit="s",
                 bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} simulated s [{elapsed}<{remaining}]") as b:
            while not done.wait(poll_s):
                p = Path(path)
                if not p.exists():
                    continue
                with open(p, "rb") as f:
                    f.seek(offset)
                    data = f.read()
                offset += len(data)
                latest = None
                for packet in decoder.feed(data):
                    t_us = getattr(packet, "t_us", None)
                    if t_us is not None:
                        latest = unwrap(t_us)
                        first = latest if first is None else first
                if latest is not None:
                    b.n = min(round((latest - first) / 1e6, 1), b.total)
                    b.refresh()

    t = threading.Thread(target=follow, daemon=True)
    t.start()
    try:
        yield
    finally:
        done.set()
        t.join(2)
