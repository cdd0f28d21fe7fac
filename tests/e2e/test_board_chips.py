"""The virtual board's chips against their datasheets, driven by a bench I2C master (hardware/sim/probe)
over the simulated ATmega's real TWI: no sphere firmware is involved, so the firmware's expectations
cannot leak into what is checked. Each test quotes the datasheet statement it checks (sections in
hardware/sim/README.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simscenarios import probe, s16be, s16le
from sphere.sim import trace as T

HMC, ITG, ADXL, QMC = "1e", "68", "53", "0d"


def _rotating(seconds: float, dps: float = 90.0) -> T.Motion:
    return T.rotation(seconds, rate_dps=dps, still_s=0.0)


def _hmc_xyz(d):
    """HMC5883L data output registers 03..08: X, Z, Y, big-endian."""
    return s16be(d[0], d[1]), s16be(d[4], d[5]), s16be(d[2], d[3])


def _motion(seconds, gyr_dps=None, mag_uT=None, rate_hz=1000.0):
    n = int(seconds * rate_hz)
    still = T.still(seconds, rate_hz)
    gyr = np.zeros((n, 3)) if gyr_dps is None else np.radians(gyr_dps)
    mag = still.mag_uT if mag_uT is None else np.broadcast_to(mag_uT, (n, 3)).copy()
    return T.Motion(rate_hz, still.acc_m_s2, gyr, mag, "test")


# ---------------------------------------------------------------- HMC5883L

def test_hmc_rdy_stays_set_in_continuous_mode_and_a_fast_poller_rereads_samples():
    """Status register, RDY: "Set when data is written to all six data registers. Cleared when device initiates
    a write to the data output registers ... remain cleared for 250 us". Reading the data does not clear it in
    continuous-measurement mode, so a 200 Hz poller of a 75 Hz chip sees RDY = 1 almost every time and reads
    each sample ~2.7 times."""
    cmds = [(0.1, "w 1e 00 18"), (0.11, "w 1e 02 00"), (0.2, "p 1e 03 6 5000 120"), (0.9, "p 1e 09 1 5000 100")]
    r = probe(cmds, _rotating(1.5), 1.5)
    polls = r.tagged("p")
    data, status = polls[:120], polls[120:]
    assert len(status) == 100
    assert sum(p.data[0] & 1 for p in status) >= 95  # RDY is low only for 250 us per 13.3 ms sample
    samples = [tuple(p.data) for p in data]
    fresh = sum(1 for a, b in zip(samples, samples[1:]) if a != b)
    span_s = (data[-1].t_us - data[0].t_us) * 1e-6
    assert abs(fresh / span_s - 75) <= 4, (fresh, span_s)  # 75 Hz of new data, not 200


def test_hmc_rdy_low_for_250_us_around_each_write():
    """RDY is clear from the start of the write of new data for 250 us (status register; DRDY the same), once
    per sample at the output rate."""
    cmds = [(0.1, "w 1e 00 18"), (0.11, "w 1e 02 00"), (0.2, "f 1e 09 01 1500")]
    r = probe(cmds, _rotating(0.5), 0.5)
    f = r.tagged("f")
    falls = [x.t_us for x in f if not x.data[0] & 1]
    rises = [x.t_us for x in f if x.data[0] & 1]
    lows = [next(t for t in rises if t > t0) - t0 for t0 in falls if any(t > t0 for t in rises)]
    assert len(lows) >= 5
    assert all(130 <= d <= 250 + 130 for d in lows), lows  # 250 us, seen by reads ~120 us apart
    gaps = np.diff(falls) / (1e6 / 75)
    assert np.all(np.abs(gaps - np.round(gaps)) < 0.05), gaps


def test_hmc_drdy_pin_low_for_250_us_at_each_new_sample():
    """DRDY (pin description): "Low for 250 usec when data is placed in the data output registers", high
    otherwise; at 75 Hz once every 13.3 ms, with no bus traffic at all while the pin is watched."""
    cmds = [(0.1, "w 1e 00 18"), (0.11, "w 1e 02 00"), (0.2, "e 03 00 00 100")]
    r = probe(cmds, T.still(0.4), 0.4, drdy_pin="D3")
    e = r.tagged("e")
    falls = [x.t_us for x in e if x.data == [0]]
    rises = [x.t_us for x in e if x.data == [1]]
    assert len(falls) >= 7 and len(rises) >= 7
    lows = [next(t for t in rises if t > f) - f for f in falls if any(t > f for t in rises)]
    assert all(230 <= d <= 270 for d in lows), lows
    assert np.all(np.abs(np.diff(falls) - 1e6 / 75) < 40), np.diff(falls)


def _heading_deg(x, y):
    return math.degrees(math.atan2(y, x))


def test_hmc_data_output_lock_holds_the_old_sample_until_all_six_bytes_are_read():
    """LOCK (status bit 1): set when some but not all six data output registers have been read; new data is
    not placed in them until all six bytes have been read; LOCK clears then."""
    cmds = [(0.1, "w 1e 00 18"), (0.11, "w 1e 02 00"), (0.3, "r 1e 03 2"), (0.33, "r 1e 09 1"),
            (0.40, "r 1e 05 4"), (0.41, "r 1e 09 1"), (0.45, "r 1e 03 6")]
    r = probe(cmds, _rotating(0.6, 180.0), 0.6)
    partial, status_locked, rest, status_open, later = (x.data for x in r.tagged("r"))
    assert status_locked[0] & 2, "LOCK not set after a partial read"
    assert not status_open[0] & 2, "LOCK still set after all six bytes were read"
    held = _hmc_xyz(partial + rest)
    new = _hmc_xyz(later)
    # turning at 180 deg/s: the sample held from ~0.30 s is ~27 deg behind the one read at 0.45 s; had the
    # registers followed the chip, Z and Y read at 0.40 s would be only ~9 deg behind
    turn = abs((_heading_deg(new[0], new[1]) - _heading_deg(held[0], held[1]) + 180) % 360 - 180)
    assert 22 <= turn <= 32, turn
    assert abs(math.hypot(held[0], held[1]) - 0.2 * 1090) <= 3  # X and Y from one sample: the field's size


def test_hmc_single_measurement_mode_conversion_and_idle():
    """Single-measurement mode: the measurement is ready ~6 ms after the request ("Wait 6 ms"), RDY goes
    high, the mode register returns to idle; RDY stays high until the data output register is read."""
    # the power-on single measurement (RDY high until read) is read out first
    cmds = [(0.15, "r 1e 03 6"), (0.2, "w 1e 02 01"), (0.2003, "p 1e 09 1 500 30"), (0.25, "r 1e 03 6"),
            (0.26, "r 1e 09 1"), (0.3, "r 1e 02 1")]
    r = probe(cmds, T.still(0.4), 0.4)
    w = r.tagged("w")[0].t_us
    polls = r.tagged("p")
    first_rdy = next(p.t_us for p in polls if p.data[0] & 1)
    assert 5000 <= first_rdy - w <= 7000, first_rdy - w
    assert not r.tagged("r")[2].data[0] & 1, "RDY still high after the data were read in single mode"
    assert r.tagged("r")[3].data[0] & 3 in (2, 3), "mode register not back to idle"


@pytest.mark.parametrize("crb,lsb_per_gauss", [(0x20, 1090), (0xE0, 230), (0x00, 1370)])
def test_hmc_gain(crb, lsb_per_gauss):
    """Configuration register B, GN2..GN0: 1370, 1090, 820, 660, 440, 390, 330, 230 LSB/gauss."""
    cmds = [(0.1, f"w 1e 01 {crb:02x}"), (0.11, "w 1e 02 01"), (0.2, "r 1e 03 6")]
    r = probe(cmds, T.still(0.3), 0.3)
    x, y, z = _hmc_xyz(r.tagged("r")[0].data)
    field_g = T.EARTH_FIELD_ENU_UT / 100.0  # still, z up, x east: the field in the sensor frame, gauss
    assert abs(y - field_g[1] * lsb_per_gauss) <= 2 and abs(z - field_g[2] * lsb_per_gauss) <= 2 and abs(x) <= 1


def test_hmc_overflow_reads_minus_4096():
    """Data output registers: an ADC over- or underflow on a channel reads -4096 until the next valid one."""
    strong = np.array([170.0, 20.0, -45.0])  # 1.7 gauss on x: in range at gain 1, over it at gain 0
    cmds = [(0.1, "w 1e 01 00"), (0.11, "w 1e 02 01"), (0.2, "r 1e 03 6"), (0.3, "w 1e 01 20"),
            (0.31, "w 1e 02 01"), (0.4, "r 1e 03 6")]
    r = probe(cmds, _motion(0.5, mag_uT=strong), 0.5)
    (x0, y0, z0), (x1, y1, z1) = (_hmc_xyz(x.data) for x in r.tagged("r"))
    assert x0 == -4096 and y0 == round(0.2 * 1370) and -4096 < z0
    assert x1 == round(1.7 * 1090) and y1 == round(0.2 * 1090)


def test_hmc_positive_self_test():
    """Self test: CRA 0x71, CRB 0xA0 (gain 5), continuous: X and Y ~ +452, Z ~ +421 (1.16 / 1.08 Ga), whatever
    the ambient field (the unbiased acquisition is subtracted); limits 243..575 at gain 5."""
    cmds = [(0.1, "w 1e 00 71"), (0.11, "w 1e 01 a0"), (0.12, "w 1e 02 00"), (0.4, "r 1e 03 6")]
    r = probe(cmds, _rotating(0.5), 0.5)
    x, y, z = _hmc_xyz(r.tagged("r")[0].data)
    assert (x, y, z) == (452, 452, 421)
    assert all(243 <= v <= 575 for v in (x, y, z))


def test_hmc_continuous_mode_first_sample_after_two_periods():
    """Continuous-measurement mode: "the first measurement set is available ... after a period of 2/fDO" after
    the write to the mode register, then one every 1/fDO (15 Hz here)."""
    cmds = [(0.1, "w 1e 00 10"), (0.15, "r 1e 03 6"), (0.2, "w 1e 02 00"), (0.2001, "p 1e 03 6 2000 160")]
    r = probe(cmds, _rotating(0.6, 180.0), 0.6)
    w = r.tagged("w")[1].t_us
    polls = r.tagged("p")
    changes = [b.t_us for a, b in zip(polls, polls[1:]) if a.data != b.data]
    assert 2e6 / 15 - 2500 <= changes[0] - w <= 2e6 / 15 + 2500, changes[0] - w
    assert all(abs(d - 1e6 / 15) < 2500 for d in np.diff(changes)), np.diff(changes)


def test_hmc_noise_floor():
    """Table 1, noise floor: 2 milli-gauss standard deviation (100 samples, no averaging), with --noise."""
    cmds = [(0.1, "w 1e 00 18"), (0.11, "w 1e 01 a0"), (0.12, "w 1e 02 00"), (0.2, "p 1e 03 6 13334 100")]
    r = probe(cmds, T.still(1.6), 1.6, noise=True, seed=4)
    xyz = np.array([_hmc_xyz(p.data) for p in r.tagged("p")], float) / 390.0 * 1000.0  # milli-gauss at gain 5
    sd = xyz.std(axis=0)
    assert np.all((2.0 * 0.6 <= sd) & (sd <= 2.0 * 1.5)), sd  # 1-LSB steps of 2.6 mG at this gain


# ---------------------------------------------------------------- ITG-3200

def test_itg_start_up_time():
    """Section 3.1, start-up time from power on: 50 ms; the outputs come only after it (here after H_RESET)."""
    cmds = [(0.2, "w 68 3e 80"), (0.2002, "w 68 16 1b"), (0.2004, "w 68 15 04"), (0.2006, "f 68 1a 01 1000")]
    r = probe(cmds, T.still(0.4), 0.4)
    reset = r.tagged("w")[0].t_us
    first = next(x.t_us for x in r.tagged("f") if x.data[0] & 1)
    assert 50000 - 200 <= first - reset <= 50000 + 5000 + 500, first - reset  # the write's own time before it

def test_itg_temperature_register():
    """TEMP_OUT: -13200 LSB at 35 degC, 280 LSB/degC (section 3.1); the ambient board is at 25 degC, and
    with --noise the die warms after power-on (the model's warm-up), reported in the same register."""
    cmds = [(0.2, "w 68 3e 01"), (0.3, "r 68 1b 2"), (2.9, "r 68 1b 2")]
    cold = probe(cmds, T.still(3.0), 3.0)
    t0, t1 = (s16be(*x.data) for x in cold.tagged("r"))
    assert t0 == t1 == -13200 + 280 * (25 - 35)
    warm = probe(cmds, T.still(3.0), 3.0, noise=True, seed=3)
    w0, w1 = (s16be(*x.data) for x in warm.tagged("r"))
    assert w1 > w0 >= -16000  # warming: about 0.19 degC (53 LSB) in the first 3 s


def _gyro_series(dlpf_cfg: int, motion, seconds, t0=0.3, n=200, period_us=5000, div=4, **kw):
    cmds = [(0.1, "w 68 3e 01"), (0.11, f"w 68 15 {div:02x}"), (0.12, f"w 68 16 {0x18 | dlpf_cfg:02x}"),
            (t0, f"p 68 1d 6 {period_us} {n}")]
    r = probe(cmds, motion, seconds, **kw)
    p = r.tagged("p")
    return np.array([p_.t_us for p_ in p]) * 1e-6, np.array([[s16be(d[0], d[1]), s16be(d[2], d[3]), s16be(d[4], d[5])]
                                                              for d in (p_.data for p_ in p)], float), r


@pytest.mark.parametrize("cfg,bw_hz", [(3, 42.0), (5, 10.0)])
def test_itg_dlpf_bandwidth(cfg, bw_hz):
    """Register 22, DLPF_CFG: the low-pass bandwidth (42 Hz for 3, 10 Hz for 5): a rotation rate oscillating at
    the bandwidth comes out at about -3 dB, one at a fifth of it nearly whole."""
    def amplitude(f_hz):
        t = np.arange(int(2.0 * 1000)) / 1000.0
        gyr = np.zeros((len(t), 3))
        gyr[:, 2] = 200.0 * np.sin(2 * np.pi * f_hz * t)
        # the trace at 1 kHz and SMPLRT_DIV 0: the chip's own filter is all that shapes the output
        ct = T.to_chips(_motion(2.0, gyr_dps=gyr), gyro_rate_hz=1000.0)
        ts, g, _ = _gyro_series(cfg, ct, 2.0, t0=0.5, n=300, period_us=3000, div=0)
        # least-squares fit of a sine at f_hz
        A = np.stack([np.sin(2 * np.pi * f_hz * ts), np.cos(2 * np.pi * f_hz * ts), np.ones_like(ts)], 1)
        c = np.linalg.lstsq(A, g[:, 2] / 14.375, rcond=None)[0]
        return math.hypot(c[0], c[1]) / 200.0
    assert 0.6 <= amplitude(bw_hz) <= 0.8
    assert amplitude(bw_hz / 5) >= 0.95


def test_itg_noise_and_turn_on_bias():
    """Section 3.1: total RMS noise 0.38 deg/s at 100 Hz bandwidth (DLPF_CFG 2); a turn-on zero-rate offset
    within the +-40 deg/s tolerance, the same all through a short still run."""
    _, g, _ = _gyro_series(2, T.still(1.5), 1.5, n=200, noise=True, seed=5)
    rms = g.std(axis=0) / 14.375
    assert np.all((0.38 * 0.6 <= rms) & (rms <= 0.38 * 1.4)), rms
    bias = g.mean(axis=0) / 14.375
    assert np.all(np.abs(bias) < 40) and np.any(np.abs(bias) > 0.05), bias


def test_itg_own_oscillator_sets_the_sample_rate():
    """The ITG-3200 samples on its own clock (internal oscillator, a few % off): with SMPLRT_DIV 4 and a
    +2 % oscillator, 204 samples a second of the Nano's time instead of 200 (RAW_DATA_RDY, register 26,
    cleared by reading it)."""
    def rate(ppm):
        cmds = [(0.1, "w 68 3e 01"), (0.11, "w 68 15 04"), (0.12, "w 68 16 1b"), (0.3, "n 68 1a 01 1000")]
        kw = {"clock_ppm": [f"itg3200:{ppm}"]} if ppm else {}
        r = probe(cmds, T.still(1.4), 1.4, **kw)
        (line,) = r.tagged("n")
        return line.data[0]  # "n CCCC elapsed": the count, hex
    assert abs(rate(0) - 200) <= 1
    assert abs(rate(20000) - 204) <= 1


# ---------------------------------------------------------------- ADXL345

def test_adxl_samples_on_its_own_clock():
    """The ADXL345's output data rate comes from its own oscillator: 100 Hz (BW_RATE 0x0A) on a clock 1 % fast
    gives 101 new samples a second of the Nano's time (the sphere turning, so each sample differs)."""
    def rate(ppm):
        cmds = [(0.1, "w 53 31 0b"), (0.11, "w 53 2c 0a"), (0.12, "w 53 2d 08"), (0.2, "d 53 32 6 1000")]
        kw = {"clock_ppm": [f"adxl345:{ppm}"]} if ppm else {}
        r = probe(cmds, T.rotation(1.3, rate_dps=90.0, axis=(1.0, 0.0, 0.0), still_s=0.0), 1.3, **kw)
        return r.tagged("d")[0].data[0]
    assert abs(rate(0) - 100) <= 1 and abs(rate(10000) - 101) <= 1


def test_adxl_noise_at_100_hz():
    """Table 1: noise 0.75 LSB rms on x and y, 1.1 LSB rms on z, at 100 Hz output data rate, full resolution."""
    cmds = [(0.1, "w 53 31 0b"), (0.11, "w 53 2c 0a"), (0.12, "w 53 2d 08"), (0.3, "p 53 32 6 10000 150")]
    r = probe(cmds, T.still(1.9), 1.9, noise=True, seed=11)
    a = np.array([[s16le(d[0], d[1]), s16le(d[2], d[3]), s16le(d[4], d[5])] for d in (p.data for p in r.tagged("p"))], float)
    sd = a.std(axis=0)
    assert 0.75 * 0.7 <= sd[0] <= 0.75 * 1.3 and 0.75 * 0.7 <= sd[1] <= 0.75 * 1.3 and 1.1 * 0.7 <= sd[2] <= 1.1 * 1.3, sd


def test_a_chip_that_goes_away_in_the_middle_of_a_read_leaves_sda_to_the_pull_ups():
    """A chip that stops answering in the middle of a burst read drives SDA no more: the master reads 1s, 0xFF,
    for the rest of the burst (its own TWI reports each byte received: it drives the acknowledge itself), never
    the chip's last byte again (the model did that before: a firmware's gyro read cut so read 0x4F4F, 1412 deg/s).
    The ITG-3200 turning steadily is read 16 bytes at a time, 20 times, each time going away about 1 ms after the
    command at a phase that moves by 0.13 ms from read to read: the reads it cuts read the same data as the
    others up to the cut, then 0xFF to the end."""
    ts = [0.15 + 0.02 * i + 0.00013 * i for i in range(20)]
    cmds = [(0.05, "w 68 3e 01"), (0.06, "w 68 16 1b")] + [(t, "r 68 1d 16") for t in ts]
    nacks = [f"itg3200:{t + 0.0012:.5f}:{t + 0.0042:.5f}" for t in ts]
    r = probe(cmds, T.rotation(0.6, rate_dps=300.0, axis=(0.6, 0.0, 0.8), still_s=0.1), 0.6, board="aligned",
              nack=nacks)
    reads = [x.data for x in r.tagged("r") if x.data]
    whole = [d for d in reads if 0xFF not in d]
    cut = [d for d in reads if 0xFF in d]
    assert len(whole) >= 5 and len(cut) >= 3, reads
    for d in cut:
        k = d.index(0xFF)
        assert k >= 1 and d[k:] == [0xFF] * (16 - k) and d[:k] == whole[0][:k], d


# ---------------------------------------------------------------- QMC5883L

def test_qmc5883l_variant_register_map():
    """QMC5883L (GY-85 clone): address 0x0D (0x1E does not answer), chip ID register 0DH = 0xFF; control 1
    (09H) 0x15 = continuous, 50 Hz, 8 G (3000 LSB/G), OSR 512; data X, Y, Z little-endian at 00H..05H;
    status 06H: DRDY set on new data and cleared by reading a data register, DOR when a sample was skipped."""
    cmds = [(0.05, "r 1e 0a 3"), (0.06, "r 0d 0d 1"), (0.1, "w 0d 0b 01"), (0.11, "w 0d 09 15"),
            (0.2, "r 0d 06 1"), (0.21, "r 0d 00 7"), (0.3, "r 0d 06 1")]
    r = probe(cmds, T.still(0.4), 0.4, board="gy85-qmc")
    hmc, chip_id, st0, data, st2 = (x.data for x in r.tagged("r"))
    assert hmc is None and chip_id == [0xFF]
    assert st0[0] & 1 and st0[0] & 4  # new data; and the samples before it were never read (skipped)
    x, y, z = s16le(data[0], data[1]), s16le(data[2], data[3]), s16le(data[4], data[5])
    # GY-85 mounting: the magnetometer reads (body y, -body x, body z)
    assert abs(x - 0.20 * 3000) <= 3 and y == 0 and abs(z + 0.45 * 3000) <= 3  # the trace's gain-1 rounding
    assert not data[6] & 5  # status read in the same burst, after the data: DRDY and DOR cleared
    assert st2[0] & 1 and st2[0] & 4  # 90 ms later: new data, and the samples in between were skipped


def test_qmc5883l_soft_reset_and_pointer_roll_over():
    """Control 2 (0AH): SOFT_RST restores every register's default (control 1 back to 0: standby);
    ROL_PNT makes the pointer roll over from 06H to 00H in a burst read."""
    cmds = [(0.1, "w 0d 09 15"), (0.11, "w 0d 0a 40"), (0.2, "r 0d 00 6"), (0.201, "r 0d 05 3"),
            (0.21, "w 0d 0a 80"), (0.22, "r 0d 09 2")]
    r = probe(cmds, T.still(0.3), 0.3, board="gy85-qmc")
    data, burst, after_reset = (x.data for x in r.tagged("r"))
    assert data[0] == 0x58  # X = 600 (0.2 gauss at 3000 LSB/G): its LSB, distinct from 07H's (0 at 25 degC)
    assert burst[2] == data[0]  # 05H, 06H, then 00H again instead of 07H
    assert after_reset == [0x00, 0x00]


# ---------------------------------------------------------------- board variants

@pytest.mark.parametrize("board,gyro_x_sign,mag_xy", [("aligned", 1, (0, 218)), ("sen10724", 1, (-218, 0)),
                                                      ("gy85", -1, (218, 0))])
def test_board_variant_axis_mounting(board, gyro_x_sign, mag_xy):
    """Each chip's axes as mounted on the board (README, "Board variants"): a turn about the body's x axis at
    90 deg/s shows on the gyro's own signed axis, and the field's northward 20 uT (body y) on the
    magnetometer's; the accelerometer defines the body axes."""
    cmds = [(0.05, "w 68 3e 01"), (0.06, "w 68 16 1b"), (0.07, "w 53 31 0b"), (0.08, "w 53 2d 08"),
            (0.09, "w 1e 02 01"), (0.19, "r 1e 03 6"), (0.19, "r 53 32 6"), (0.5, "r 68 1d 6")]
    r = probe(cmds, T.rotation(0.6, rate_dps=90.0, axis=(1.0, 0.0, 0.0), still_s=0.2), 0.6, board=board)
    m, a, g = (x.data for x in r.tagged("r"))
    assert s16be(g[0], g[1]) == gyro_x_sign * round(90 * 14.375)
    assert s16le(a[4], a[5]) == 256
    mx, my, mz = _hmc_xyz(m)
    assert (mx, my) == mag_xy and mz == -490


# ---------------------------------------------------------------- bus faults and power

def test_sda_held_at_power_up_until_nine_clocks():
    """A sensor left mid-read by a reset holds SDA low: no transaction completes (the TWI cannot make a START)
    until the master clocks the byte out (nine SCL pulses) and sends a STOP."""
    cmds = [(0.1, "r 68 00 1"), (0.2, "c"), (0.3, "r 68 00 1")]
    r = probe(cmds, T.still(0.4), 0.4, sda_held=True)
    before, after = r.tagged("r")
    assert before.data is None and after.data == [0x68]


def test_reset_mid_read_leaves_the_chip_holding_sda():
    """An AVR reset in the middle of a read: the chip keeps SDA low after the AVR restarts."""
    cmds = [(0.1, "p 68 1d 6 1000 50"), (0.3, "r 68 00 1"), (0.4, "c"), (0.5, "r 68 00 1")]
    r = probe(cmds, T.still(0.6), 0.6, reset_mid_read=[0.12])
    assert r.stats["resets"] == 1
    assert r.stats["glitches"]["sda_held"] == 1
    held, cleared = r.tagged("r")
    assert held.data is None and cleared.data == [0x68]


def test_brownout_restarts_the_chips_at_power_on_values():
    """A brown-out: the AVR restarts and so do the chips (HMC5883L CRA back to its default 0x10)."""
    cmds = [(0.1, "w 1e 00 18"), (0.15, "r 1e 00 1"), (0.4, "r 1e 00 1")]
    r = probe(cmds, T.still(0.5), 0.5, brownout=[0.2])
    a, b = r.tagged("r")
    assert a.data == [0x18] and b.data == [0x10]
    assert r.stats["resets"] == 1 and b.t_us < 0.25e6  # the AVR's clock (micros) started again at 0.2 s


def test_glitches_are_seeded_and_counted():
    """--glitch RATE --seed N: single NACKs, stretched clocks and resets mid-read at random, the same for the
    same seed."""
    cmds = [(0.1, "p 68 1d 6 2000 400")]
    a = probe(cmds, T.still(1.0), 1.0, glitch=20, seed=7)
    b = probe(cmds, T.still(1.0), 1.0, glitch=20, seed=7)
    assert a.stats["faults"] == b.stats["faults"] and a.stats["faults"]
    kinds = {f["kind"] for f in a.stats["faults"]}
    assert kinds & {"glitch_nack", "clock_stretch", "reset_mid_read"}


def test_watchdog_reset_restarts_the_program_with_wdrf():
    """A watchdog reset (ATmega328P datasheet, "Watchdog System Reset", MCUSR): the program starts with PORF
    (bit 0) at power-on and again with WDRF (bit 3) after the watchdog; the board counts it in `resets`; the
    chips keep their registers (they kept power)."""
    cmds = [(0.1, "w 1e 00 18"), (0.5, "W"), (0.8, "r 1e 00 1")]
    r = probe(cmds, T.still(1.0), 1.0)
    banners = r.tagged("probe")
    assert [b.data[0] for b in banners] == [1, 8], banners
    assert r.stats["resets"] == 1
    assert r.tagged("r")[0].data == [0x18]


# ---------------------------------------------------------------- the ATmega328P's resets: MCUSR and SRAM
# ATmega328P datasheet, "System Control and Reset": "Reset Sources" (power-on, external, watchdog, brown-out),
# "MCU Status Register - MCUSR" (PORF "set if a Power-on Reset occurs"; EXTRF, BORF, WDRF "set if an External /
# Brown-out / Watchdog System Reset occurs. The bit is reset by a Power-on Reset, or by writing a logic zero to
# the flag"), "Resetting the AVR" ("During reset, all I/O Registers are set to their initial values": SRAM is not
# one, and no reset source writes it). The probe prints MCUSR as it found it and four .noinit SRAM bytes as they
# were, then writes 5a a5 c3 3c there (hardware/sim/probe/probe.cpp).

MARK = [0x5A, 0xA5, 0xC3, 0x3C]
PORF, EXTRF, BORF, WDRF = 1, 2, 4, 8


def _banners(r):
    return [(b.data[0], b.data[1:]) for b in r.tagged("probe")]


@pytest.mark.parametrize("kind, flag", [("reset_at", EXTRF), ("brownout", BORF)])
def test_a_reset_that_is_not_a_power_on_sets_its_flag_and_keeps_sram(kind, flag):
    """External reset (the reset pin: a host's DTR, --reset-at) -> EXTRF; brown-out (the supply below the BOD
    level, not below the power-on threshold) -> BORF; SRAM as the program left it."""
    r = probe([], T.still(0.6), 0.6, **{kind: [0.3]})
    (c0, _), (c1, m1) = _banners(r)
    assert c0 == PORF and c1 == flag and m1 == MARK, _banners(r)


def test_a_watchdog_reset_keeps_sram():
    r = probe([(0.3, "W")], T.still(0.6), 0.6)
    (c0, _), (c1, m1) = _banners(r)
    assert c0 == PORF and c1 == WDRF and m1 == MARK


def test_a_reset_mid_read_is_an_external_reset():
    """The board's reset in the middle of a read pulls the reset pin: EXTRF, SRAM kept. The banner after it
    follows the line the reset cut, on the same line of the capture, so the program keeps MCUSR (`k`) and a
    watchdog reset afterwards shows both flags."""
    r = probe([(0.05, "k"), (0.1, "p 68 1d 6 1000 50"), (0.3, "W")], T.still(0.5), 0.5, reset_mid_read=[0.12])
    assert [f["kind"] for f in r.stats["faults"]] == ["reset_mid_read"] and r.stats["resets"] == 2
    (c0, _), *_, (c2, m2) = _banners(r)
    assert c0 == PORF and c2 == EXTRF | WDRF and m2 == MARK, _banners(r)


def test_power_on_sets_porf_alone_and_sram_is_not_defined():
    """A power-on reset (at start and --power-off): MCUSR = PORF only (the other flags "reset by a Power-on
    Reset"), SRAM not what the program left (the model: seeded random bytes, different per power-on)."""
    r = probe([(0.1, "k")], T.still(0.8), 0.8, reset_at=[0.2], power_off=[0.5])
    (c0, m0), (c1, m1), (c2, m2) = _banners(r)
    assert c0 == PORF and c1 == EXTRF and m1 == MARK
    assert c2 == PORF and m2 != MARK and m2 != m0, _banners(r)  # EXTRF (left set by `k`) cleared by the power-on
    assert [f["kind"] for f in r.stats["faults"]] == ["reset", "power_off"]


def test_reset_flags_accumulate_until_the_program_clears_them():
    """EXTRF, BORF and WDRF are reset only by a power-on or by writing 0: a program that leaves MCUSR alone
    (`k`) finds the earlier reset's flag beside the new one."""
    r = probe([(0.1, "k"), (0.4, "k"), (0.7, "W")], T.still(1.0), 1.0, reset_at=[0.3], brownout=[0.5])
    assert [c for c, _ in _banners(r)] == [PORF, EXTRF, EXTRF | BORF, EXTRF | BORF | WDRF], _banners(r)


# ---------------------------------------------------------------- the ADXL345's FIFO (datasheet rev. E, "FIFO",
# "Register 0x38—FIFO_CTL", "Register 0x39—FIFO_STATUS") and its registers over an AVR reset


def _entries(r):
    """FIFO_STATUS's entries from the one-byte reads (the data reads are six bytes)."""
    return [x.data[0] & 0x3F for x in r.tagged("r") if len(x.data) == 1]


def test_adxl_stream_mode_keeps_the_newest_32_and_reading_takes_the_oldest_out():
    """Stream mode: "the FIFO holds the last 32 data values. When the FIFO is full, the oldest data is
    overwritten with newer data"; FIFO_STATUS's entries count them; each read of the data registers takes the
    oldest set out. At 100 Hz (BW_RATE 0x0A) the FIFO fills in 0.32 s; reading 5 sets leaves 27 (28 when a new
    set came in the meantime, one every 10 ms). Back in bypass the FIFO is empty (the model's FIFO_STATUS then
    counts the data registers' set, as before the FIFO was modelled)."""
    cmds = [(0.1, "w 53 38 9f"), (0.12, "w 53 2d 08"), (0.6, "r 53 39 1")]
    cmds += [(0.61 + 0.0005 * i, "r 53 32 6") for i in range(5)]
    cmds += [(0.615, "r 53 39 1"), (0.62, "w 53 38 00"), (0.63, "r 53 39 1")]
    r = probe(cmds, T.still(0.7), 0.7)
    full, after, bypass = _entries(r)
    assert full == 32 and after in (27, 28) and bypass <= 1, r.lines
    # the sets taken out are the oldest: 0.6 s - 32 x 10 ms old, which the board says too
    assert r.stats["adxl345_data_age_ms"]["max"] > 300


def test_adxl_fifo_mode_stops_when_full_and_the_watermark_counts_samples():
    """FIFO mode "collects up to 32 values and then stops collecting data"; the watermark bit in INT_SOURCE is
    set while the FIFO holds at least FIFO_CTL's samples (here 10) and DATA_READY while a set is waiting."""
    cmds = [(0.1, "w 53 38 4a"), (0.11, "w 53 2d 08"), (0.15, "r 53 30 1"), (0.5, "r 53 39 1"), (0.6, "r 53 39 1"),
            (0.61, "r 53 30 1")]
    r = probe(cmds, T.still(0.7), 0.7)
    src0, src1 = r.tagged("r")[0].data[0], r.tagged("r")[3].data[0]
    assert _entries(r)[1:3] == [32, 32], r.lines  # full at 0.43 s, and it stays 32
    assert not src0 & 0x02 and src1 & 0x82 == 0x82, r.lines  # 4 sets at 0.15 s: no watermark yet


def test_adxl_registers_survive_an_avr_reset_and_a_power_on_clears_them():
    """The chips keep their power over an AVR reset (the reset pin: a reflash, a DTR): FIFO_CTL and the offsets
    stay as an earlier program left them; a power-on restores their reset values (0)."""
    cmds = [(0.1, "w 53 38 9f"), (0.12, "w 53 1e 05"), (0.4, "r 53 38 1"), (0.41, "r 53 1e 1"), (0.7, "r 53 38 1"),
            (0.71, "r 53 1e 1")]
    r = probe(cmds, T.still(0.8), 0.8, reset_at=[0.3], power_off=[0.5])
    assert [x.data[0] for x in r.tagged("r")] == [0x9F, 0x05, 0x00, 0x00], r.lines


# ---------------------------------------------------------------- the bus's levels and timing (hardware/sim/mcu.c)


def test_the_bus_model_flags_the_avr_pull_ups_and_a_line_driven_high():
    """Arduino's Wire turns the ATmega's pull-ups (20-50 kOhm to 5 V) on beside the sensor board's (to 3.3 V): the
    idle level, (5/20k + 3.3/4.7k) / (1/20k + 1/4.7k) = 3.62 V, is above the ADXL345's VDD I/O + 0.3 V = 3.6 V.
    The probe's bus clear sets a pin as an output while its port bit is 1 (the pull-up): 5 V on the line."""
    r = probe([(0.1, "c")], T.still(0.2), 0.2)
    bus = r.stats["bus"]
    assert bus["avr_pullup_events"] > 0 and abs(bus["first_avr_pullup_s"]) < 0.01
    assert bus["driven_high_events"] > 0 and 0.1 <= bus["first_driven_high_s"] < 0.11
    assert bus["over_limit"] and bus["idle_high_v_max"] == 5.0
    r = probe([], T.still(0.2), 0.2, bus_pullup_kohm=10)
    assert r.stats["bus"]["idle_high_v_max"] == pytest.approx((5 / 20 + 3.3 / 10) / (1 / 20 + 1 / 10), abs=1e-3)
