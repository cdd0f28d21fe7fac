"""BROAD trials (Laidig et al., Data 6(7):72, 2021, CC BY 4.0): loading and the dataset's error metric.

The trials are not part of the repository. They are found in :func:`sphere.paths.broad_dir`
(``SPHERE_BROAD_DIR``, default ``../shared/data/broad`` beside the checkout). Outside this team, get
them from the dataset's public repository (``dlaidig/broad`` on GitHub, folder ``data_mat``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.io import loadmat

from sphere import quaternion as quat
from sphere.errors import SphereError
from sphere.paths import broad_dir

WHERE_TO_GET = (
    "BROAD is the Berlin Robust Orientation Estimation Assessment Dataset (CC BY 4.0); clone its "
    "public repository (github.com/dlaidig/broad) and point SPHERE_BROAD_DIR at its data_mat folder"
)


class BroadMissing(SphereError, FileNotFoundError):
    """The BROAD trials are not where the settings say."""


@dataclass(frozen=True)
class Trial:
    """One BROAD trial in the dataset's units."""

    name: str
    rate_hz: float
    gyr_rad_s: np.ndarray  # (N, 3)
    acc_m_s2: np.ndarray  # (N, 3)
    mag_uT: np.ndarray  # (N, 3)
    opt_quat: np.ndarray  # (N, 4) w, x, y, z, sensor-to-ENU; NaN where the optical system lost the body
    movement: np.ndarray  # (N,) bool, samples that count in the error

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    def __len__(self) -> int:
        return len(self.gyr_rad_s)

    def seconds(self, start_s: float, duration_s: float) -> "Trial":
        """A slice of the trial, by time."""
        a = int(round(start_s * self.rate_hz))
        b = a + int(round(duration_s * self.rate_hz))
        return Trial(
            self.name,
            self.rate_hz,
            self.gyr_rad_s[a:b],
            self.acc_m_s2[a:b],
            self.mag_uT[a:b],
            self.opt_quat[a:b],
            self.movement[a:b],
        )


def trial_paths(directory: Path | str | None = None) -> list[Path]:
    """Every ``.mat`` trial in the folder, sorted by name; :class:`BroadMissing` when there are none."""
    d = Path(directory) if directory is not None else broad_dir()
    paths = sorted(d.glob("*.mat")) if d.is_dir() else []
    if not paths:
        raise BroadMissing(f"no BROAD trials (*.mat) in {d}; {WHERE_TO_GET}")
    return paths


def find_trial(name: str, directory: Path | str | None = None) -> Path:
    """A trial by file name, stem, or number prefix (``24`` finds ``24_disturbed_tapping_A.mat``)."""
    p = Path(name)
    if p.suffix == ".mat" and p.is_file():
        return p
    if p.exists() or "/" in name:  # a path, not a name: say what is wrong with it rather than look it up
        what = "is a folder" if p.is_dir() else "is not a .mat file" if p.exists() else "does not exist"
        raise BroadMissing(f"{name} {what}: give a BROAD trial's .mat file, or a trial's name or number (e.g. 07) "
                           f"in {directory or broad_dir()}")
    for path in trial_paths(directory):
        if path.stem == name or path.name == name or path.stem.split("_", 1)[0] == name:
            return path
    raise BroadMissing(f"no BROAD trial named {name!r} in {directory or broad_dir()}")


def load_trial(path: Path | str) -> Trial:
    path = Path(path)
    try:
        d = loadmat(str(path))
    except FileNotFoundError:
        raise BroadMissing(f"{path} does not exist; {WHERE_TO_GET}") from None
    except Exception as e:  # scipy raises several types for a damaged file
        raise ValueError(f"{path} is not a readable BROAD .mat file: {e}") from None
    missing = [k for k in ("imu_gyr", "imu_acc", "imu_mag", "opt_quat", "movement", "sampling_rate") if k not in d]
    if missing:
        raise ValueError(f"{path} lacks the BROAD fields {', '.join(missing)}")
    return Trial(
        name=path.stem,
        rate_hz=float(np.asarray(d["sampling_rate"]).ravel()[0]),
        gyr_rad_s=np.ascontiguousarray(d["imu_gyr"], dtype=float),
        acc_m_s2=np.ascontiguousarray(d["imu_acc"], dtype=float),
        mag_uT=np.ascontiguousarray(d["imu_mag"], dtype=float),
        opt_quat=np.ascontiguousarray(d["opt_quat"], dtype=float),
        movement=np.asarray(d["movement"]).ravel().astype(bool),
    )


@dataclass(frozen=True)
class OrientationError:
    """RMSE in degrees over the samples that count (movement phases with a finite reference)."""

    total: float
    heading: float
    inclination: float

    def as_dict(self) -> dict[str, float]:
        return {"total": self.total, "heading": self.heading, "inclination": self.inclination}


def error_angles_deg(q_est_enu: np.ndarray, q_opt_enu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-sample total, heading and inclination errors (degrees) as the dataset's authors define them.

    q_err = q_est ⊗ q_opt⁻¹ (error in the earth frame); total = 2·acos(|w|), heading = 2·atan(|z/w|),
    inclination = 2·acos(√(w² + z²)). Both inputs are sensor-to-ENU.
    """
    e = quat.multiply(quat.normalize(q_est_enu), quat.conjugate(quat.normalize(q_opt_enu)))
    w, z = np.abs(e[:, 0]), e[:, 3]
    total = 2.0 * np.arccos(np.clip(w, 0.0, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        heading = 2.0 * np.arctan(np.abs(z / w))
    inclination = 2.0 * np.arccos(np.clip(np.sqrt(w * w + z * z), 0.0, 1.0))
    return np.degrees(total), np.degrees(heading), np.degrees(inclination)


def orientation_error(q_est_enu: np.ndarray, trial: Trial) -> OrientationError:
    """The dataset's metric for one trial: RMSE over movement samples with a finite reference."""
    q_est_enu = np.asarray(q_est_enu, dtype=float)
    if q_est_enu.shape != trial.opt_quat.shape:
        raise ValueError(f"estimate has shape {q_est_enu.shape}, the trial's reference {trial.opt_quat.shape}")
    use = trial.movement & np.all(np.isfinite(trial.opt_quat), axis=1) & np.all(np.isfinite(q_est_enu), axis=1)
    if not use.any():
        raise ValueError(f"trial {trial.name} has no movement samples with a finite reference")
    t, h, i = error_angles_deg(q_est_enu[use], trial.opt_quat[use])
    rms = lambda x: float(np.sqrt(np.mean(x * x)))  # noqa: E731
    return OrientationError(rms(t), rms(h), rms(i))
