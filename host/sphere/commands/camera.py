"""`sphere camera`: calibrate a camera from board images; render a BROAD trial as the virtual webcam sees it."""

from __future__ import annotations

import csv
import os
import sys
import time

from sphere import argtypes, broad
from sphere.bench import camera as camera_bench
from sphere.camera import trials
from sphere.camera.intrinsics import CalibrationError, calibrate, read_views
from sphere.camera.live import CameraError, CameraSource
from sphere.camera.model import Camera, CameraFileError

HELP = "camera tools: intrinsics from chessboard images (calibrate); the virtual webcam (render); the ball in a webcam or video (track); timing (bench)"
DESCRIPTION = """\
calibrate: the camera's focal lengths, principal point and lens distortion from 5 or more images of a
printed chessboard or ChArUco board (OpenCV's calibrateCamera), written as the JSON file that `sphere hybrid-eval
--camera-file` and the tracker read.
render: frames of a BROAD trial's ball (8 cm, at the trial's optical positions) as the virtual webcam
sees them, to an .avi (MJPG) with a .csv of each frame's exposure and arrival times."""


def add_arguments(p) -> None:
    sub = p.add_subparsers(dest="camera_command", metavar="ACTION")
    c = sub.add_parser("calibrate", help="intrinsics from chessboard images")
    c.add_argument("images", nargs="+", help="image files, folders of images, or videos (every 10th frame)")
    c.add_argument("--board", default="9x6", help="squares across x down on the printed board (default 9x6)")
    c.add_argument("--square-mm", type=float, default=25.0, help="side of one square in mm (default 25)")
    c.add_argument("--charuco", type=float, metavar="MARKER_MM",
                   help="the board is a ChArUco board (ArUco DICT_5X5_100) with markers this size in mm")
    c.add_argument("-o", "--output", default="camera.json", help="where to write the camera file")
    r = sub.add_parser("render", help="the virtual webcam's view of a BROAD trial")
    r.add_argument("--trial", default="16", help="BROAD trial name or number (default 16)")
    r.add_argument("--start", type=argtypes.non_negative, default=30.0, help="seconds into the trial (default 30)")
    r.add_argument("--seconds", type=argtypes.seconds, default=5.0, help="how long (default 5)")
    r.add_argument("--distance", type=argtypes.distance_m, default=1.0,
                   help="camera to the mean ball position, m (default 1, at most 10)")
    r.add_argument("-o", "--output", default="virtual-camera.avi", help="the video to write")
    k = sub.add_parser("track", help="the ball's position in a webcam's or a video's frames (camera only)")
    k.add_argument("source", help="webcam index (0, 1 ...) or a video file")
    k.add_argument("--camera-file", help="intrinsics from `sphere camera calibrate` (default: a typical 60° webcam)")
    k.add_argument("--hue", type=argtypes.hue_deg, default=120.0, help="the ball's hue in degrees (default 120, green)")
    k.add_argument("--seconds", type=argtypes.non_negative, default=0.0, help="stop after this long (default: until the end)")
    camera_bench.add_arguments(sub.add_parser("bench", help=camera_bench.HELP))

def _board(text: str):
    try:
        a, b = (int(v) for v in text.lower().split("x"))
        if a < 3 or b < 3:
            raise ValueError
        return a, b
    except ValueError:
        print(f"sphere camera: --board {text!r} must be squares across x down, e.g. 9x6 (each ≥ 3)", file=sys.stderr)
        raise SystemExit(2) from None


def run(args) -> int:
    if args.camera_command is None:
        print("sphere camera: say what to do: calibrate, render, track or bench (see sphere camera --help)", file=sys.stderr)
        return 2
    try:
        import cv2  # noqa: F401  (optional dependency: the camera extra (OpenCV))
    except ImportError:
        print("sphere camera: OpenCV is missing; install the camera extra: pip install -e '.[camera]'",
              file=sys.stderr)
        return 1
    if args.camera_command == "calibrate":
        return _calibrate(args)
    if args.camera_command == "bench":
        return camera_bench.run(args)
    if args.camera_command == "track":
        return _track(args)
    return _render(args)


def _track(args) -> int:
    try:
        cam = Camera.load(args.camera_file) if args.camera_file else None
        src = CameraSource(args.source, cam, hue_deg=args.hue).start()
    except (CameraError, CameraFileError) as e:
        print(f"sphere camera track: {e}", file=sys.stderr)
        return 2  # a source or camera file that cannot be used: the command line's fault
    print("frame,t_exposure_s,x_m,y_m,z_m,radius_px")
    t_end = time.monotonic() + args.seconds if args.seconds > 0 else None
    t0 = None
    try:
        while src.running or not src.fixes.empty():
            for f in src.poll():
                t0 = f.t_exposure if t0 is None else t0
                x, y, z = f.center_cam
                print(f"{f.index},{f.t_exposure - t0:.4f},{x:.4f},{y:.4f},{z:.4f},{f.radius_px:.2f}", flush=True)
            if t_end is not None and time.monotonic() > t_end:
                break
            time.sleep(0.005)
    finally:
        src.stop()
    print(f"{src.frames} frames, ball in {src.found}", file=sys.stderr)
    if src.error:
        print(f"sphere camera track: the camera stopped: {src.error}", file=sys.stderr)
        return 1
    return 0


def _calibrate(args) -> int:
    cols, rows = _board(args.board)
    if not args.square_mm > 0:
        print("sphere camera: --square-mm must be positive", file=sys.stderr)
        return 2
    if args.charuco is not None and not 0 < args.charuco < args.square_mm:
        print("sphere camera: --charuco (the marker size) must be positive and smaller than --square-mm",
              file=sys.stderr)
        return 2
    for path in args.images:
        if not os.path.exists(path):  # a typo: a usage error (2), not a calibration that failed (1)
            print(f"sphere camera calibrate: {path} does not exist", file=sys.stderr)
            return 2
    try:
        res = calibrate(list(read_views(args.images)), cols, rows, args.square_mm / 1000.0,
                        None if args.charuco is None else args.charuco / 1000.0)
    except CalibrationError as e:
        print(f"sphere camera calibrate: {e}", file=sys.stderr)
        return 1
    c = res.camera
    c.save(args.output)
    print(f"{len(res.used)} views used, {len(res.skipped)} without the board"
          + (f" ({', '.join(res.skipped[:5])}{' ...' if len(res.skipped) > 5 else ''})" if res.skipped else ""))
    print(f"{c.width}x{c.height}: fx {c.fx:.2f} fy {c.fy:.2f} px, principal point ({c.cx:.2f}, {c.cy:.2f}), "
          f"distortion k1 {c.dist[0]:+.4f} k2 {c.dist[1]:+.4f} p1 {c.dist[2]:+.5f} p2 {c.dist[3]:+.5f} "
          f"k3 {c.dist[4]:+.4f}")
    print(f"reprojection RMS {c.rms_px:.3f} px (worst view {max(res.per_view_rms_px):.3f} px)")
    print(f"wrote {args.output}")
    return 0


def _render(args) -> int:
    import cv2  # optional dependency: the camera extra (OpenCV)

    try:
        rt = trials.rendered_trial(args.trial, args.start, args.seconds, distance_m=args.distance)
    except (broad.BroadMissing, ValueError) as e:
        print(f"sphere camera render: {e}", file=sys.stderr)
        return 1
    cam = rt.scene.camera
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # our own line says what went wrong
    out = cv2.VideoWriter(args.output, cv2.VideoWriter_fourcc(*"MJPG"), rt.scene.fps, (cam.width, cam.height))
    if not out.isOpened():
        print(f"sphere camera render: cannot write {args.output} (use a .avi name in a writable folder)",
              file=sys.stderr)
        return 1
    with open(args.output + ".csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "exposure_start_s", "exposure_mid_s", "arrival_s", "ball_x_m", "ball_y_m", "ball_z_m"])
        for k, fr in enumerate(rt.frames()):
            out.write(fr.image)
            w.writerow([k, f"{fr.t_start:.6f}", f"{fr.t_mid:.6f}", f"{fr.t_arrival:.6f}",
                        *(f"{v:.5f}" for v in fr.truth_cam)])
    out.release()
    # OpenCV does not report a failed write: a video shorter than its frames' headers is a full disk
    if os.path.getsize(args.output) < 64 * (k + 1):
        print(f"sphere camera render: cannot write {args.output}: the disk is full or read-only; make room "
              "(or write it somewhere else)", file=sys.stderr)
        return 1
    print(f"wrote {args.output} ({k + 1} frames, {cam.width}x{cam.height} at {rt.scene.fps:g} fps) and {args.output}.csv")
    return 0
