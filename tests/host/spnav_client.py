"""A libspnav client through ctypes on Debian's real libspnav (libspnav0): what a program such as Blender
or FreeCAD does — ``spnav_open`` (which reads ``$SPNAV_SOCKET``), the device queries, then events —
printing one JSON line per event with the time it arrived (CLOCK_MONOTONIC, seconds), and at the end the
object rotation that libspnav's own ``spnav_posrot_moveobj`` accumulated from the motion events.

    python tests/host/spnav_client.py SECONDS      (exits after SECONDS, or when the daemon closes)

Not a pytest module: the tests and the bench run it as a process (libspnav keeps one connection per
process in globals).
"""

import ctypes
import json
import select
import sys
import time


class Motion(ctypes.Structure):  # struct spnav_event_motion (spnav.h)
    _fields_ = [("type", ctypes.c_int), ("x", ctypes.c_int), ("y", ctypes.c_int), ("z", ctypes.c_int),
                ("rx", ctypes.c_int), ("ry", ctypes.c_int), ("rz", ctypes.c_int), ("period", ctypes.c_uint),
                ("data", ctypes.c_void_p)]


class Button(ctypes.Structure):  # struct spnav_event_button
    _fields_ = [("type", ctypes.c_int), ("press", ctypes.c_int), ("bnum", ctypes.c_int)]


class Event(ctypes.Union):  # spnav_event (the largest member is the motion; padded to be safe)
    _fields_ = [("type", ctypes.c_int), ("motion", Motion), ("button", Button), ("pad", ctypes.c_char * 128)]


class PosRot(ctypes.Structure):  # struct spnav_posrot: pos[3], rot[4] = x, y, z, w
    _fields_ = [("pos", ctypes.c_float * 3), ("rot", ctypes.c_float * 4)]


SPNAV_EVENT_MOTION, SPNAV_EVENT_BUTTON = 1, 2


def out(**kw):
    print(json.dumps(kw), flush=True)


def main() -> int:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    lib = ctypes.CDLL("libspnav.so.0")
    t0 = time.monotonic()
    if lib.spnav_open() == -1:
        out(kind="error", what="spnav_open failed")
        return 1
    proto = lib.spnav_protocol()
    lib.spnav_client_name(b"sphere test client (ctypes)")
    buf = ctypes.create_string_buffer(256)
    n = lib.spnav_dev_name(buf, len(buf))
    out(kind="open", t=time.monotonic(), open_s=time.monotonic() - t0, proto=proto,
        name=buf.value.decode(errors="replace") if n >= 0 else None,
        axes=lib.spnav_dev_axes(), buttons=lib.spnav_dev_buttons())
    pr = PosRot()
    lib.spnav_posrot_init(ctypes.byref(pr))
    fd = lib.spnav_fd()
    ev = Event()
    end = time.monotonic() + seconds
    closed = False
    while time.monotonic() < end and not closed:
        r, _, _ = select.select([fd], [], [], 0.2)
        if not r:
            continue
        got = False
        while lib.spnav_poll_event(ctypes.byref(ev)):
            got = True
            now = time.monotonic()
            if ev.type == SPNAV_EVENT_MOTION:
                m = ev.motion
                lib.spnav_posrot_moveobj(ctypes.byref(pr), ctypes.byref(m))
                out(kind="motion", t=now, v=[m.x, m.y, m.z, m.rx, m.ry, m.rz], period=m.period)
            elif ev.type == SPNAV_EVENT_BUTTON:
                out(kind="button", t=now, press=ev.button.press, bnum=ev.button.bnum)
        if not got:  # readable but no event: the daemon closed the socket
            closed = True
    out(kind="end", t=time.monotonic(), closed=closed, pos=list(pr.pos), rot_xyzw=list(pr.rot))
    lib.spnav_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
