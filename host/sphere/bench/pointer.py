"""Pointer quality on real motion: jitter at rest, lag in motion, overshoot after a stop, speed.

What it does, per BROAD trial of the dataset's ``with_breaks`` group (trials.json):

1. The gyroscope is resampled to the sphere's 200 Hz clock. The ITG-3200 is noisier than BROAD's IMU,
   so white noise of the ITG-3200's datasheet rate noise (0.38 °/s RMS per axis, ``--gyro-noise-dps``,
   fixed seed) is added. Its bias is removed with the mean over the trial's rest samples (a stand-in for
   the daemon's at-rest bias estimate, the same for every filter).
2. The daemon's own :class:`PointerMapper` (local axes, no smoothing, no tightening, no acceleration) at
   its default sensitivity turns it into pointer velocity; its integral is the unfiltered pointer path.
3. Each filter runs per sample on that path (pointer position in px); JoyShockMapper-style smoothing
   and tightening (the daemon's mapper with its defaults) is the second reference.

Figures:

- ``jitter_px``: over rest phases (from 1 s after motion stops), RMS distance of the pointer from a
  straight-line fit over each 1-s window — the shake a person sees, not slow drift.
- ``lag_ms``: the delay (parabola-refined) that maximises the cross-correlation between filtered and
  unfiltered pointer velocity over movement samples, searched over 0–200 ms.
- ``overshoot_px``: mean over stops (motion → rest) of how far past the unfiltered stopping point the
  filtered pointer goes, along the last direction of motion, in the 0.5 s after the stop.
- ``slow_gain``: on constant slow turns of 1, 2 and 4 °/s (3 s each, same gyro noise, synthetic), the
  filtered pointer's displacement over the true one after the first second: what tightening or a dead
  zone takes away from deliberate slow motion (1.0 = nothing; lag does not lower it).
- ``us_per_sample``: time of one filter update in this process.

Tuning rule (fixed, the same for every filter family): the setting with the least lag among those with
jitter below 0.3 px that keep slow motion (slow gain ≥ 0.9 — otherwise "least lag" would reward
swallowing slow moves); lag ties go to the least jitter, and if none qualifies, the least jitter wins.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass

import numpy as np

HELP = "pointer jitter at rest, lag in motion and overshoot for every smoothing filter, on BROAD trials"

RATE_HZ = 200.0
JITTER_LIMIT_PX = 0.3
ITG3200_NOISE_DPS = 0.38  # datasheet: total RMS noise, 100 Hz bandwidth


def add_arguments(p) -> None:
    p.add_argument("--trials", help="BROAD folder (default: SPHERE_BROAD_DIR or ../shared/data/broad)")
    p.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    p.add_argument("--gyro-noise-dps", type=float, default=ITG3200_NOISE_DPS, help="added gyro noise, °/s RMS per axis (default: ITG-3200 datasheet 0.38)")
    p.add_argument("--seconds", type=float, help="use only the first S seconds of each trial (quick look)")
    p.add_argument("--filters", help="comma-separated filter families (default: all)")
    p.add_argument("--all-settings", action="store_true", help="print every setting tried, not only each family's pick")


@dataclass
class Track:
    """One trial's unfiltered pointer path and its phases, at RATE_HZ."""

    name: str
    position: np.ndarray  # (N, 2) px
    movement: np.ndarray  # (N,) bool
    gyro_dps: np.ndarray  # (N, 3) bias-removed, for the mapper-based reference


def with_breaks_trials(directory=None):
    from sphere.broad import trial_paths

    paths = trial_paths(directory)
    meta = paths[0].parent / "trials.json"
    if meta.exists():
        groups = json.loads(meta.read_text())["trials"]
        chosen = [p for p in paths if "with_breaks" in groups.get(p.stem, {}).get("groups", [])]
    else:
        chosen = [p for p in paths if "with_breaks" in p.stem]
    if not chosen:
        from sphere.broad import BroadMissing

        raise BroadMissing(f"no trial of the with_breaks group in {paths[0].parent}")
    return chosen


def make_track(path, noise_dps: float, seconds: float | None, seed: int = 7) -> Track:
    from sphere.broad import load_trial

    trial = load_trial(path)
    t_src = np.arange(len(trial)) / trial.rate_hz
    t = np.arange(0.0, t_src[-1], 1.0 / RATE_HZ)
    if seconds:
        t = t[: int(seconds * RATE_HZ)]
    gyro = np.stack([np.interp(t, t_src, np.degrees(trial.gyr_rad_s[:, k])) for k in range(3)], axis=1)
    movement = trial.movement[np.minimum(np.rint(t * trial.rate_hz).astype(int), len(trial) - 1)]
    rng = np.random.default_rng(seed)
    gyro = gyro + rng.normal(0.0, noise_dps, gyro.shape)
    if (~movement).any():
        gyro = gyro - gyro[~movement].mean(axis=0)
    return track_from_gyro(path.stem, gyro, movement)


def track_from_gyro(name: str, gyro_dps: np.ndarray, movement: np.ndarray) -> Track:
    """The unfiltered pointer path: the daemon's mapper with smoothing, tightening and acceleration off."""
    from sphere.daemon.pointer import PointerMapper, PointerSettings

    mapper = PointerMapper(PointerSettings(tightening_dps=0.0, smoothing_dps=0.0, axes="local"))
    mapper.settings.fast_deg_per_width = mapper.settings.slow_deg_per_width
    dt = 1.0 / RATE_HZ
    velocity = np.array([mapper.rate_px_s(g, None, dt) for g in gyro_dps])
    return Track(name, np.cumsum(velocity * dt, axis=0), movement, gyro_dps)


SLOW_RATES_DPS = (1.0, 2.0, 4.0)


def slow_sweeps(noise_dps: float, seed: int = 11) -> list[Track]:
    """Constant slow turns (1, 2, 4 °/s about the sensor's z axis for 3 s) with the same gyro noise."""
    rng = np.random.default_rng(seed)
    n = int(3.0 * RATE_HZ)
    tracks = []
    for rate in SLOW_RATES_DPS:
        gyro = np.zeros((n, 3))
        gyro[:, 2] = rate
        tracks.append(track_from_gyro(f"sweep_{rate:g}dps", gyro + rng.normal(0.0, noise_dps, gyro.shape), np.ones(n, bool)))
    return tracks


def slow_gain(paths: list[np.ndarray], sweeps: list[Track]) -> float:
    """How much of slow, deliberate motion survives: on each constant slow sweep, the filtered pointer's
    displacement over the true (noise-free) one between 1 s and 3 s, averaged over the sweeps (1.0 = kept
    whole; tightening and dead zones lower it, lag does not)."""
    from sphere.daemon.pointer import PointerMapper, PointerSettings

    px_per_deg = PointerMapper().screen_width_px / PointerSettings().slow_deg_per_width
    a, b = int(1.0 * RATE_HZ), -1
    gains = []
    for path, sweep, rate in zip(paths, sweeps, SLOW_RATES_DPS):
        true_px = rate * (len(sweep.position) - 1 - a) / RATE_HZ * px_per_deg
        gains.append(abs(float(path[b, 0] - path[a, 0])) / true_px)
    return float(np.mean(gains))


#: The daemon mapper's smoothing and tightening (JoyShockMapper's ideas), tuned by the same rule.
JSM_GRID = {"tightening_dps": [0.0, 0.5, 1.0, 2.0], "smoothing_dps": [0.0, 4.0, 8.0], "smoothing_time_s": [0.03, 0.06]}


def jsm_path(track: Track, **params) -> np.ndarray:
    from sphere.daemon.pointer import PointerMapper, PointerSettings

    settings = PointerSettings(axes="local", **params)
    settings.fast_deg_per_width = settings.slow_deg_per_width
    mapper = PointerMapper(settings)
    dt = 1.0 / RATE_HZ
    v = np.array([mapper.rate_px_s(g, None, dt) for g in track.gyro_dps])
    return np.cumsum(v * dt, axis=0)


def _runs(mask: np.ndarray):
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def jitter_px(path: np.ndarray, movement: np.ndarray) -> tuple[float, int]:
    """RMS distance from a line fit over 1-s windows in rest phases; also the sample count used."""
    win = int(RATE_HZ)
    skip = int(1.0 * RATE_HZ)
    sq, n = 0.0, 0
    x = np.arange(win)
    for a, b in _runs(~movement):
        a += skip
        for s in range(a, b - win + 1, win):
            seg = path[s : s + win]
            coef = np.polyfit(x, seg, 1)
            resid = seg - (np.outer(x, coef[0]) + coef[1])
            sq += float(np.sum(resid * resid))
            n += win
    return (math.sqrt(sq / n) if n else float("nan")), n


def lag_ms(filtered: np.ndarray, raw: np.ndarray, movement: np.ndarray, max_ms: float = 200.0) -> float:
    """Delay of the filtered pointer velocity behind the unfiltered one, refined between samples by a
    parabola through the correlation peak (shifts from −25 ms are searched so a peak at 0 refines too)."""
    vf = np.diff(filtered, axis=0)
    vr = np.diff(raw, axis=0)
    use = movement[1:]
    kmax = int(max_ms / 1000.0 * RATE_HZ)
    kmin = -int(0.025 * RATE_HZ)
    n = len(vr)
    corr = []
    for k in range(kmin, kmax + 1):
        lo, hi = max(0, -k), min(n, n - k)
        m = use[lo:hi]
        a = vr[lo:hi][m]
        b = vf[lo + k : hi + k][m]
        corr.append(float(np.sum(a * b)) / math.sqrt(float(np.sum(a * a)) * float(np.sum(b * b)) + 1e-30))
    corr = np.array(corr)
    i = int(np.argmax(corr))
    frac = 0.0
    if 0 < i < len(corr) - 1:
        c0, c1, c2 = corr[i - 1], corr[i], corr[i + 1]
        denom = c0 - 2 * c1 + c2
        if denom < 0:
            frac = 0.5 * (c0 - c2) / denom
    return (i + kmin + frac) / RATE_HZ * 1000.0


def overshoot_px(filtered: np.ndarray, raw: np.ndarray, movement: np.ndarray) -> float:
    look_back, look_ahead = int(0.1 * RATE_HZ), int(0.5 * RATE_HZ)
    values = []
    for a, b in _runs(~movement):
        if a < look_back or b - a < look_ahead:
            continue
        step = raw[a] - raw[a - look_back]
        norm = float(np.linalg.norm(step))
        if norm < 1.0:
            continue
        u = step / norm
        ahead = (filtered[a : a + look_ahead] - raw[a]) @ u
        values.append(max(0.0, float(ahead.max())))
    return float(np.mean(values)) if values else 0.0


SLOW_GAIN_MIN = 0.9


def run_filter(factory, params: dict, path: np.ndarray) -> tuple[np.ndarray, float]:
    f = factory(**params)
    dt = 1.0 / RATE_HZ
    out = np.empty_like(path)
    rows = path.tolist()
    update = f.update
    t0 = time.perf_counter()
    for i, x in enumerate(rows):
        out[i] = update(x, dt)
    us = (time.perf_counter() - t0) / len(rows) * 1e6
    return out, us


def measure(tracks: list[Track], paths: list[np.ndarray], us: float) -> dict:
    sq, n = 0.0, 0
    lags, overs = [], []
    for track, path in zip(tracks, paths):
        j, m = jitter_px(path, track.movement)
        if m:
            sq += j * j * m
            n += m
        lags.append(lag_ms(path, track.position, track.movement))
        overs.append(overshoot_px(path, track.position, track.movement))
    return {
        "jitter_px": math.sqrt(sq / n) if n else float("nan"),
        "lag_ms": float(np.mean(lags)),
        "overshoot_px": float(np.mean(overs)),
        "us_per_sample": us,
    }


def acceptable(r: dict) -> bool:
    return r["jitter_px"] < JITTER_LIMIT_PX and r["slow_gain"] >= SLOW_GAIN_MIN


def pick(rows: list[dict]) -> dict:
    """The tuning rule: least lag among settings with jitter below the limit that keep slow motion
    (slow gain ≥ 0.9); lag ties (to 0.1 ms) go to the least jitter; if none qualifies, the least jitter."""
    ok = [r for r in rows if acceptable(r)]
    if ok:
        return min(ok, key=lambda r: (round(r["lag_ms"], 1), r["jitter_px"]))
    return min(rows, key=lambda r: r["jitter_px"])


def evaluate(tracks: list[Track], families: list[str], sweeps: list[Track]) -> dict[str, list[dict]]:
    from sphere.smoothing.registry import FILTERS, grid

    results: dict[str, list[dict]] = {}
    for family in families:
        factory, _ = FILTERS[family]
        rows = []
        for params in grid(family) or [{}]:
            outs, times = [], []
            for track in tracks:
                out, us = run_filter(factory, params, track.position)
                outs.append(out)
                times.append(us)
            swept = [run_filter(factory, params, sw.position)[0] for sw in sweeps]
            rows.append({**measure(tracks, outs, float(np.median(times))), "slow_gain": slow_gain(swept, sweeps), "params": params})
        results[family] = rows
    # JoyShockMapper-style reference: the daemon mapper's own smoothing + tightening, over its grid
    import itertools

    rows = []
    keys = list(JSM_GRID)
    for values in itertools.product(*(JSM_GRID[k] for k in keys)):
        params = dict(zip(keys, values))
        if params["smoothing_dps"] == 0.0 and params["smoothing_time_s"] != JSM_GRID["smoothing_time_s"][0]:
            continue  # smoothing off: its time does not matter
        t0 = time.perf_counter()
        paths = [jsm_path(t, **params) for t in tracks]
        us = (time.perf_counter() - t0) / sum(len(t.position) for t in tracks) * 1e6
        swept = [jsm_path(sw, **params) for sw in sweeps]
        rows.append({**measure(tracks, paths, us), "slow_gain": slow_gain(swept, sweeps), "params": params})
    results["jsm-mapper"] = rows
    return results


def run(args) -> int:
    from sphere.broad import BroadMissing
    from sphere.smoothing.registry import FILTERS

    try:
        paths = with_breaks_trials(args.trials)
    except BroadMissing as e:
        print(f"sphere bench pointer: {e}", file=sys.stderr)
        return 2
    families = args.filters.split(",") if args.filters else list(FILTERS)
    unknown = [f for f in families if f not in FILTERS]
    if unknown:
        print(f"sphere bench pointer: unknown filter {', '.join(unknown)}; choose from {', '.join(FILTERS)}", file=sys.stderr)
        return 2
    tracks = [make_track(p, args.gyro_noise_dps, args.seconds) for p in paths]
    results = evaluate(tracks, families, slow_sweeps(args.gyro_noise_dps))
    picks = {family: pick(rows) for family, rows in results.items()}
    smoothing = {f: r for f, r in picks.items() if f not in ("none",)}
    default = min(
        (f for f, r in smoothing.items() if acceptable(r)),
        key=lambda f: (round(smoothing[f]["lag_ms"], 1), smoothing[f]["jitter_px"]),
        default=min(smoothing, key=lambda f: smoothing[f]["jitter_px"]),
    )
    from sphere.daemon.pointer import PointerSettings

    print(
        f"pointer quality on {', '.join(t.name for t in tracks)} at 200 Hz; {PointerSettings().slow_deg_per_width:g}° per "
        f"1920-px screen width; added gyro noise {args.gyro_noise_dps:g} °/s RMS; rule: least lag with jitter < {JITTER_LIMIT_PX} px and slow gain ≥ {SLOW_GAIN_MIN}"
    )
    header = f"{'filter':<22} {'jitter px':>9} {'lag ms':>7} {'overshoot px':>12} {'slow gain':>9} {'µs/sample':>9}  setting"
    print(header)
    for family, rows in results.items():
        shown = rows if args.all_settings else [picks[family]]
        for r in shown:
            mark = "*" if family == default and r is picks[family] else " "
            params = " ".join(f"{k}={v:g}" for k, v in r["params"].items())
            print(f"{mark}{family:<21} {r['jitter_px']:9.3f} {r['lag_ms']:7.1f} {r['overshoot_px']:12.2f} {r['slow_gain']:9.2f} {r['us_per_sample']:9.1f}  {params}")
    print(f"* default (the rule's pick across families): {default}")
    if args.json:
        out = {"filters": {}, "default": default, "rule": f"least lag with jitter < {JITTER_LIMIT_PX} px and slow gain >= {SLOW_GAIN_MIN}",
               "gyro_noise_dps": args.gyro_noise_dps, "trials": [t.name for t in tracks]}
        for family, r in picks.items():
            out["filters"][family] = {k: r[k] for k in ("jitter_px", "lag_ms", "overshoot_px", "slow_gain", "us_per_sample")} | {
                "params": r["params"], "settings_tried": len(results[family])}
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0
