"""The camera's intrinsics from images of a printed chessboard or ChArUco board (OpenCV's calibrateCamera).

The board is given as the squares one counts on it (9×6 squares have 8×5 inner corners, which OpenCV
finds). A ChArUco board (a chessboard with ArUco markers, DICT_5X5_100, in its white squares) may be
seen in part: each corner is identified by its markers, so views with the board cut by the image edge
or a finger still count. Corners are refined to sub-pixel accuracy; the views where the board is not
found are reported and left out; at least :data:`MIN_VIEWS` must remain.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sphere.camera.model import Camera
from sphere.errors import SphereError

MIN_VIEWS = 5
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class CalibrationError(SphereError, ValueError):
    """Calibration cannot go on (one line: what was wrong, what to do)."""


@dataclass
class Result:
    camera: Camera
    used: list  # names of the views used
    skipped: list  # names of the views where the board was not found
    per_view_rms_px: list


def board_points(cols: int, rows: int, square_m: float) -> np.ndarray:
    """Inner corners of a cols × rows squares board, in the board's plane (z = 0), metres, OpenCV's order."""
    ic, ir = cols - 1, rows - 1
    g = np.zeros((ic * ir, 3), np.float32)
    g[:, :2] = np.mgrid[0:ic, 0:ir].T.reshape(-1, 2) * square_m
    g[:, :2] += square_m  # the first inner corner is one square in from the board's corner
    return g


def find_corners(gray: np.ndarray, cols: int, rows: int):
    """The inner corners (N, 2) to sub-pixel accuracy, or None when the board is not in the image."""
    import cv2  # optional dependency: the camera extra (OpenCV)

    pattern = (cols - 1, rows - 1)
    ok, corners = cv2.findChessboardCorners(gray, pattern, cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), crit)
    return corners.reshape(-1, 2)


CHARUCO_DICTIONARY = 6  # cv2.aruco.DICT_5X5_100
MIN_CHARUCO_CORNERS = 8


def charuco_board(cols: int, rows: int, square_m: float, marker_m: float):
    import cv2  # optional dependency: the camera extra (OpenCV)

    return cv2.aruco.CharucoBoard((cols, rows), square_m, marker_m,
                                  cv2.aruco.getPredefinedDictionary(CHARUCO_DICTIONARY))


def _charuco_points(detector, board, gray):
    """(object points, image points) of the ChArUco corners found, or None."""
    cc, ci, _, _ = detector.detectBoard(gray)
    if cc is None or len(cc) < MIN_CHARUCO_CORNERS:
        return None
    obj, imgp = board.matchImagePoints(cc, ci)
    return obj.reshape(-1, 3).astype(np.float32), imgp.reshape(-1, 2).astype(np.float32)


def calibrate(views, cols: int, rows: int, square_m: float, charuco_marker_m: float | None = None) -> Result:
    """``views``: (name, grey uint8 image) pairs, all of one size. With ``charuco_marker_m`` the board is a
    ChArUco board with markers that size."""
    import cv2  # optional dependency: the camera extra (OpenCV)

    board = detector = None
    if charuco_marker_m is not None:
        board = charuco_board(cols, rows, square_m, charuco_marker_m)
        detector = cv2.aruco.CharucoDetector(board)
    obj, img, used, skipped = [], [], [], []
    size = None
    for name, gray in views:
        if size is None:
            size = gray.shape[::-1]
        elif gray.shape[::-1] != size:
            raise CalibrationError(f"{name} is {gray.shape[1]}x{gray.shape[0]}, the others {size[0]}x{size[1]}; "
                                   f"calibrate one camera mode at a time")
        if board is not None:
            found = _charuco_points(detector, board, gray)
        else:
            c = find_corners(gray, cols, rows)
            found = None if c is None else (board_points(cols, rows, square_m), c.astype(np.float32))
        if found is None:
            skipped.append(name)
            continue
        obj.append(found[0])
        img.append(found[1])
        used.append(name)
    if len(used) < MIN_VIEWS:
        kind = "ChArUco board" if board is not None else "board"
        raise CalibrationError(f"the {cols}x{rows}-square {kind} was found in {len(used)} of "
                               f"{len(used) + len(skipped)} images; at least {MIN_VIEWS} are needed (check --board: "
                               f"count the squares, and show the whole board, tilted, in different places)")
    rms, K, D, rvecs, tvecs = cv2.calibrateCamera(obj, img, size, None, None)
    per_view = []
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        p, _ = cv2.projectPoints(o, r, t, K, D)
        per_view.append(float(np.sqrt(np.mean(np.sum((p.reshape(-1, 2) - i) ** 2, axis=1)))))
    d = np.zeros(5)
    d[:min(5, D.size)] = D.ravel()[:5]
    cam = Camera(int(size[0]), int(size[1]), float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                 tuple(float(v) for v in d), float(rms))
    return Result(cam, used, skipped, per_view)


def read_views(paths, every: int = 10):
    """(name, grey image) from image files, folders of them, or videos (every n-th frame)."""
    import cv2  # optional dependency: the camera extra (OpenCV)

    files = []
    for p in map(Path, paths):
        if p.is_dir():
            files += sorted(q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES)
        elif p.exists():
            files.append(p)
        else:
            raise CalibrationError(f"{p} does not exist")
    if not files:
        raise CalibrationError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {', '.join(map(str, paths))}")
    for f in files:
        if f.suffix.lower() in IMAGE_SUFFIXES:
            g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
            if g is None:
                raise CalibrationError(f"{f} is not an image OpenCV can read")
            yield f.name, g
            continue
        cap = cv2.VideoCapture(str(f))
        if not cap.isOpened():
            raise CalibrationError(f"{f} is neither an image nor a video OpenCV can read")
        k = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            if k % every == 0:
                yield f"{f.name}#{k}", cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            k += 1
        cap.release()
