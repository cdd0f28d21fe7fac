"""One side of ``sphere bench pointer --against REV``: the daemon of whatever ``sphere`` is on PYTHONPATH, fed frames.

Run as ``python -P _pointer_side.py FRAMES.npz OUT.npz`` with ``PYTHONPATH=<that revision's host/>``: every array of
FRAMES.npz is one recording's RAW_SAMPLE frames (bytes as the wire carries them); for each, a SphereMouse with its
default config on the memory backend (1920 px wide) is fed them through PacketStream and SphereMouse.handle, and
the pointer after every RAW_SAMPLE — device time, whole pixels and with the mapper's sub-pixel remainder, (N, 5) — is
written under the same name (:func:`pointer`, also the drift bench's daemon path). Only the daemon's long-standing entry points are used (SphereMouse, Config,
RecordingBackend, PacketStream), so that a revision from before this bench's figures can be measured by them.
"""

from __future__ import annotations

import sys

import numpy as np

from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.protocol import PacketStream, RawSample


def pointer(frames: bytes, d=None) -> np.ndarray:
    """(t_s device time, x, y, x exact, y exact) after every RAW_SAMPLE of ``frames`` fed to the SphereMouse ``d``
    (default: the default config on the memory backend, 1920 px wide; exact = with the mapper's sub-pixel
    remainder)."""
    d = d or SphereMouse(Config(), None, RecordingBackend((1920, 1080)), log=lambda m: None)
    out = []
    for dp in PacketStream().feed(frames):
        d.handle(dp)
        if dp.packet.TYPE == RawSample.TYPE:
            r = d.mapper.remainder
            b = d.backend
            out.append((dp.t_us * 1e-6, b.x, b.y, b.x + r[0], b.y + r[1]))
    return np.array(out, dtype=float)


def main(src: str, dst: str) -> None:
    with np.load(src) as frames:
        np.savez(dst, **{name: pointer(frames[name].tobytes()) for name in frames.files})


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
