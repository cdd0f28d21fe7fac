/*
 * sensors.c - register-level models of the ADXL345, ITG-3200 and HMC5883L (or QMC5883L) on simavr's TWI
 * bus, with the ADXL345's tap, double-tap and free-fall engine, fed by a recorded motion trace; each chip
 * on its own oscillator, mounted as on a board variant, with its datasheet's noise (README.md).
 *
 * Part of the MARG sphere's virtual board (hardware/sim).
 * Copyright (C) 2026 the MARG sphere developers
 *
 * This program is free software: you can redistribute it and/or modify it under the terms of the
 * GNU General Public License as published by the Free Software Foundation, either version 3 of the
 * License, or (at your option) any later version. It links simavr, which is GPL-3.0.
 *
 * This program is distributed in the hope that it will be useful, but WITHOUT ANY WARRANTY; without
 * even the implied warranty of MERCHANTABILITY or FITNESS FOR A PARTICULAR PURPOSE. See the GNU
 * General Public License for more details. You should have received a copy of the GNU General Public
 * License along with this program. If not, see <https://www.gnu.org/licenses/>.
 *
 * The bus protocol follows simavr's own I2C parts (parts/i2c_eeprom.c): the AVR's TWI raises
 * TWI_IRQ_OUTPUT messages (START with the address byte, WRITE with a data byte, READ asking for a
 * byte, STOP); a slave answers on TWI_IRQ_INPUT with ACK (address or written byte accepted) or with
 * READ carrying the byte. A slave that sends no ACK is a NACK.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "avr_twi.h"
#include "avr_ioport.h"
#include "sim_time.h"
#include "sim_io.h"
#include "sensors.h"

/* ---------------------------------------------------------------- trace */

static int read_exact(FILE *f, void *p, size_t n) { return fread(p, 1, n, f) == n ? 0 : -1; }

int trace_load(trace_t *t, const char *path, char *err, size_t errlen)
{
	memset(t, 0, sizeof(*t));
	FILE *f = fopen(path, "rb");
	if (!f) {
		snprintf(err, errlen, "cannot open trace %s", path);
		return -1;
	}
	char magic[8];
	uint32_t version;
	if (read_exact(f, magic, 8) || memcmp(magic, "SPHTRACE", 8) || read_exact(f, &version, 4) || version != 1) {
		snprintf(err, errlen, "%s is not a sphere trace (version 1); make one with `sphere sim`", path);
		fclose(f);
		return -1;
	}
	trace_stream_t *s[3] = {&t->accel, &t->gyro, &t->mag};
	for (int i = 0; i < 3; i++) {
		if (read_exact(f, &s[i]->rate_hz, 8) || read_exact(f, &s[i]->count, 4) || s[i]->rate_hz <= 0) {
			snprintf(err, errlen, "%s: truncated header of stream %d", path, i);
			fclose(f);
			return -1;
		}
		size_t n = (size_t)s[i]->count * 3;
		s[i]->xyz = calloc(n ? n : 3, sizeof(int16_t));
		if (n && read_exact(f, s[i]->xyz, n * sizeof(int16_t))) {
			snprintf(err, errlen, "%s: truncated data of stream %d", path, i);
			fclose(f);
			return -1;
		}
	}
	fclose(f);
	return 0;
}

const int16_t *trace_at(const trace_stream_t *s, double t_s)
{
	static const int16_t zero[3] = {0, 0, 0};
	if (!s->count)
		return zero;
	double k = floor(t_s * s->rate_hz + 1e-9);
	if (k < 0)
		k = 0;
	uint64_t i = (uint64_t)k;
	if (i >= s->count)
		i = s->count - 1;
	return s->xyz + 3 * i;
}

void trace_interp(const trace_stream_t *s, double t_s, double out[3])
{
	if (!s->count) {
		out[0] = out[1] = out[2] = 0;
		return;
	}
	double x = t_s * s->rate_hz;
	if (x <= 0) x = 0;
	double k = floor(x);
	uint64_t i = (uint64_t)k;
	if (i >= s->count - 1) {
		const int16_t *v = s->xyz + 3 * (s->count - 1);
		for (int a = 0; a < 3; a++) out[a] = v[a];
		return;
	}
	double f = x - k;
	const int16_t *p = s->xyz + 3 * i, *q = p + 3;
	for (int a = 0; a < 3; a++)
		out[a] = p[a] + f * (q[a] - p[a]);
}

/* ---------------------------------------------------------------- common */

double board_time_s(board_t *b) { return (double)b->avr->cycle / (double)b->avr->frequency; }

double chip_time(board_t *b, int chip, double t_s) { return t_s * (1.0 + b->imp.ppm[chip] * 1e-6); }

/* board time of a chip-time instant */
static double board_of_chip(board_t *b, int chip, double ct) { return ct / (1.0 + b->imp.ppm[chip] * 1e-6); }

static int16_t clip16(long v, long lo, long hi) { return (int16_t)(v < lo ? lo : v > hi ? hi : v); }

/* xorshift64* seeded through splitmix64: each chip draws from its own stream, so a fault on one chip
 * (or on the bus) does not change another chip's noise */
static uint64_t rng_seed(uint64_t seed, uint64_t stream)
{
	uint64_t z = seed + 0x9E3779B97F4A7C15ULL * (stream + 1);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
	z ^= z >> 31;
	return z ? z : 1;
}
static double rng_uniform(uint64_t *s)
{
	uint64_t x = *s;
	x ^= x >> 12; x ^= x << 25; x ^= x >> 27;
	*s = x;
	return ((x * 0x2545F4914F6CDD1DULL) >> 11) * (1.0 / 9007199254740992.0);
}
static double rng_gauss(uint64_t *s)
{
	double u = rng_uniform(s), v = rng_uniform(s);
	if (u < 1e-300) u = 1e-300;
	return sqrt(-2.0 * log(u)) * cos(2.0 * M_PI * v);
}

/* A body-frame vector as the chip's axes read it (the board variant's mounting). */
static void to_chip(board_t *b, int chip, const double body[3], double out[3])
{
	for (int i = 0; i < 3; i++) {
		int m = b->variant->mount[chip][i];
		int k = (m < 0 ? -m : m) - 1;
		out[i] = m < 0 ? -body[k] : body[k];
	}
}

/* ---------------------------------------------------------------- board variants */

const board_variant_t board_variants[] = {
	{"aligned", "all three chips' axes along the body axes (the board the tests were written on)",
	 {{1, 2, 3}, {1, 2, 3}, {1, 2, 3}}, MAG_HMC5883L},
	/* SparkFun 9DoF Sensor Stick: the ITG-3200 shares the ADXL345's axes; the HMC5883L is turned 90 deg
	 * about z, its axes reading (-y, x, z) of the body's (from the Razor AHRS firmware's axis assignments for
	 * SEN-10724: accelerometer and gyro both (-y, -x, -z), magnetometer (x, -y, -z) into its own frame) */
	{"sen10724", "SparkFun 9DoF Sensor Stick SEN-10724 (ADXL345, ITG-3200, HMC5883L)",
	 {{1, 2, 3}, {1, 2, 3}, {-2, 1, 3}}, MAG_HMC5883L},
	/* GY-85: the ITG-3205 turned 180 deg about z against the ADXL345, the HMC5883L 90 deg the other way: a
	 * copy of the firmware's profile, UNVERIFIED on a board (protocol/spec.md 4.2.1) */
	{"gy85", "GY-85 (ADXL345, ITG-3205, HMC5883L)", {{1, 2, 3}, {-1, -2, 3}, {2, -1, 3}}, MAG_HMC5883L},
	{"gy85-qmc", "GY-85 carrying a QMC5883L at 0x0D (sold as HMC5883L)", {{1, 2, 3}, {-1, -2, 3}, {2, -1, 3}},
	 MAG_QMC5883L},
	{NULL, NULL, {{0}}, 0},
};

const board_variant_t *board_variant_find(const char *name)
{
	for (const board_variant_t *v = board_variants; v->name; v++)
		if (!strcmp(v->name, name))
			return v;
	return NULL;
}

/* ---------------------------------------------------------------- ADXL345 */

enum {
	ADXL_DEVID = 0x00, ADXL_THRESH_TAP = 0x1D, ADXL_OFSX = 0x1E, ADXL_DUR = 0x21, ADXL_LATENT = 0x22,
	ADXL_WINDOW = 0x23, ADXL_THRESH_FF = 0x28, ADXL_TIME_FF = 0x29, ADXL_TAP_AXES = 0x2A,
	ADXL_ACT_TAP_STATUS = 0x2B, ADXL_BW_RATE = 0x2C, ADXL_POWER_CTL = 0x2D, ADXL_INT_ENABLE = 0x2E,
	ADXL_INT_MAP = 0x2F, ADXL_INT_SOURCE = 0x30, ADXL_DATA_FORMAT = 0x31, ADXL_DATAX0 = 0x32,
	ADXL_DATAZ1 = 0x37, ADXL_FIFO_CTL = 0x38, ADXL_FIFO_STATUS = 0x39,
};
enum { INT_DATA_READY = 0x80, INT_SINGLE_TAP = 0x40, INT_DOUBLE_TAP = 0x20, INT_FREE_FALL = 0x04,
       INT_WATERMARK = 0x02, INT_OVERRUN = 0x01 };

static double adxl_odr(chip_t *c)
{
	int code = c->regs[ADXL_BW_RATE] & 0x0F;
	return 3200.0 / (double)(1 << (15 - code)); /* 0xF: 3200 Hz ... 0xA: 100 Hz, 0xB: 200 Hz */
}

/* One output sample at board time t_s, full-resolution LSB (3.9 mg) with the offset registers applied,
 * unsaturated: the motion averaged over the last output period (the digital filter's bandwidth is ODR/2,
 * datasheet "Power/Bandwidth"), in the chip's axes, with its zero-g offset and noise (noise mode). The trace
 * is itself a chip's output at its own rate, already band-limited: the window is what the trace's own
 * sample period does not already cover (none at an ODR at or above the trace's rate; README). */
static void adxl_accel_fullres(board_t *b, double t_s, double odr, long out[3])
{
	double acc[3] = {0, 0, 0}, v[3];
	const int n = 8;
	double window = 1.0 / (odr * (1.0 + b->imp.ppm[CHIP_ADXL345] * 1e-6)) - 1.0 / b->trace->accel.rate_hz;
	if (window <= 0) { /* the trace's own samples are the chip's output: held as they come */
		const int16_t *a = trace_at(&b->trace->accel, t_s);
		for (int i = 0; i < 3; i++) acc[i] = a[i];
	} else
		for (int j = 0; j < n; j++) {
			trace_interp(&b->trace->accel, t_s - window * (j + 0.5) / n, v);
			for (int i = 0; i < 3; i++) acc[i] += v[i] / n;
		}
	double chip[3];
	to_chip(b, CHIP_ADXL345, acc, chip);
	/* noise: 0.75 LSB rms x/y, 1.1 LSB rms z at 100 Hz, growing with the bandwidth (Table 1, Figure 10..) */
	static const double sigma100[3] = {0.75, 0.75, 1.1};
	for (int i = 0; i < 3; i++) {
		double x = chip[i];
		if (b->imp.noise)
			x += b->adxl_offset_lsb[i] + sigma100[i] * sqrt(odr / 100.0) * rng_gauss(&b->adxl_rng);
		out[i] = lround(x) + 4L * (int8_t)b->chip[CHIP_ADXL345].regs[ADXL_OFSX + i]; /* OFS: 15.6 mg/LSB */
	}
}

static void adxl_update_int1(board_t *b)
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	uint8_t active = b->adxl_int_source & c->regs[ADXL_INT_ENABLE] & (uint8_t)~c->regs[ADXL_INT_MAP];
	int level = active ? 1 : 0;
	if (c->regs[ADXL_DATA_FORMAT] & 0x20) /* INT_INVERT: active low */
		level = !level;
	if (level != b->int1_level) {
		b->int1_level = level;
		avr_raise_irq(b->int1_pin, level);
	}
}

enum { FIFO_BYPASS = 0, FIFO_FIFO = 1, FIFO_STREAM = 2, FIFO_TRIGGER = 3 };
static int adxl_fifo_mode(chip_t *c) { return c->regs[ADXL_FIFO_CTL] >> 6; }

static void adxl_set_data(chip_t *c, const int16_t v[3])
{
	for (int i = 0; i < 3; i++) {
		c->regs[ADXL_DATAX0 + 2 * i] = (uint8_t)(v[i] & 0xFF);
		c->regs[ADXL_DATAX0 + 2 * i + 1] = (uint8_t)((uint16_t)v[i] >> 8);
	}
}

/* The FIFO's status bits in INT_SOURCE: DATA_READY while a set is waiting, WATERMARK while the FIFO holds at
 * least FIFO_CTL's samples ("a value of 0 in the samples bits immediately sets the watermark status bit") */
static void adxl_fifo_status(board_t *b)
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	int samples = c->regs[ADXL_FIFO_CTL] & 0x1F;
	if (b->adxl_fifo_n > 0) b->adxl_int_source |= INT_DATA_READY;
	else b->adxl_int_source &= (uint8_t)~INT_DATA_READY;
	if (b->adxl_fifo_n >= samples) b->adxl_int_source |= INT_WATERMARK;
	else b->adxl_int_source &= (uint8_t)~INT_WATERMARK;
}

static void adxl_fifo_drop(board_t *b, int k)
{
	if (k <= 0) return;
	if (k > b->adxl_fifo_n) k = b->adxl_fifo_n;
	memmove(b->adxl_fifo[0], b->adxl_fifo[k], sizeof(b->adxl_fifo[0]) * (size_t)(b->adxl_fifo_n - k));
	memmove(b->adxl_fifo_t, b->adxl_fifo_t + k, sizeof(double) * (size_t)(b->adxl_fifo_n - k));
	b->adxl_fifo_n -= k;
}

/* A new output sample: into the data registers (bypass), or into the FIFO ("FIFO": FIFO mode collects up to 32
 * sets and then stops; stream mode keeps the newest 32, the oldest dropped, which is an overrun; trigger mode
 * streams until the trigger event, then keeps the newest FIFO_CTL samples and collects until full), the data
 * registers holding the oldest. */
static void adxl_store_sample(board_t *b, const long a[3], double t_s)
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	uint8_t fmt = c->regs[ADXL_DATA_FORMAT];
	int range = fmt & 3;
	int16_t v[3];
	for (int i = 0; i < 3; i++) {
		if (fmt & 0x08) /* FULL_RES: 3.9 mg/LSB, 10 to 13 bits */
			v[i] = clip16(a[i], -(512L << range), (512L << range) - 1);
		else /* 10 bits, scale 256 >> range LSB/g */
			v[i] = clip16(a[i] >> range, -512, 511);
	}
	int mode = adxl_fifo_mode(c);
	if (mode == FIFO_BYPASS) {
		if (c->has_sample && c->data_read_sample != c->last_sample && (b->adxl_int_source & INT_DATA_READY))
			b->adxl_int_source |= INT_OVERRUN;
		adxl_set_data(c, v);
		b->adxl_data_t = t_s;
		b->adxl_int_source |= INT_DATA_READY;
		return;
	}
	int full = b->adxl_fifo_n == 32;
	if (full && (mode == FIFO_STREAM || (mode == FIFO_TRIGGER && !b->adxl_fifo_trig))) {
		adxl_fifo_drop(b, 1); /* new data replace the oldest unread */
		b->adxl_int_source |= INT_OVERRUN;
		full = 0;
	}
	if (!full) {
		memcpy(b->adxl_fifo[b->adxl_fifo_n], v, sizeof v);
		b->adxl_fifo_t[b->adxl_fifo_n++] = t_s;
	}
	adxl_set_data(c, b->adxl_fifo[0]);
	adxl_fifo_status(b);
}

/* trigger mode: an event on the interrupt pin FIFO_CTL's trigger bit names (0 INT1, 1 INT2) */
static void adxl_fifo_trigger(board_t *b)
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	if (adxl_fifo_mode(c) != FIFO_TRIGGER || b->adxl_fifo_trig)
		return;
	uint8_t events = b->adxl_int_source & c->regs[ADXL_INT_ENABLE] & (uint8_t)~(INT_DATA_READY | INT_WATERMARK | INT_OVERRUN);
	uint8_t on_pin = (c->regs[ADXL_FIFO_CTL] & 0x20) ? c->regs[ADXL_INT_MAP] : (uint8_t)~c->regs[ADXL_INT_MAP];
	if (events & on_pin) {
		b->adxl_fifo_trig = 1;
		adxl_fifo_drop(b, b->adxl_fifo_n - (c->regs[ADXL_FIFO_CTL] & 0x1F));
		if (b->adxl_fifo_n)
			adxl_set_data(c, b->adxl_fifo[0]);
		adxl_fifo_status(b);
	}
}

/* the age of the data a read returns (set sampled at t_s), for the stats */
static void adxl_note_age(board_t *b, double t_s)
{
	double age_ms = (board_time_s(b) - t_s) * 1e3;
	if (age_ms > b->adxl_age_max_ms)
		b->adxl_age_max_ms = age_ms;
	if (b->adxl_age_pending && b->adxl_first_ages < 64) {
		b->adxl_first_age_ms[b->adxl_first_ages++] = age_ms;
		b->adxl_age_pending = 0;
	}
}

/* Tap and free-fall engine on one output-data-rate sample (datasheet rev. E, figures 37-39). */
static void adxl_engine(board_t *b, uint64_t now_us, const long a[3])
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	tap_engine_t *e = &b->tap;
	uint8_t *r = c->regs;
	uint8_t axes = r[ADXL_TAP_AXES];
	long thr = 16L * r[ADXL_THRESH_TAP]; /* 62.5 mg/LSB = 16 full-res LSB */
	uint64_t dur_us = 625ULL * r[ADXL_DUR], latent_us = 1250ULL * r[ADXL_LATENT], window_us = 1250ULL * r[ADXL_WINDOW];
	int tap_enabled = (axes & 7) && r[ADXL_DUR] && r[ADXL_THRESH_TAP];
	int double_enabled = tap_enabled && r[ADXL_LATENT] && r[ADXL_WINDOW];

	uint8_t above_axes = 0;
	for (int i = 0; i < 3; i++)
		if ((axes & (4 >> i)) && labs(a[i]) > thr)
			above_axes |= (uint8_t)(4 >> i);
	int above = tap_enabled && above_axes;

	/* double-tap phases run on time */
	if (e->second == 1 && now_us >= e->first_tap_end_us + latent_us) {
		e->second = 2;
		if (above || e->suppressed) /* a tap already in progress when the window opens: invalid */
			e->second = 0;
	}
	if (e->second == 2 && now_us > e->first_tap_end_us + latent_us + window_us && !e->above)
		e->second = 0;

	if (above && !e->above) { /* rising edge */
		e->above = 1;
		e->above_start_us = now_us;
		e->above_axes = above_axes;
		if (e->second == 1 && (axes & 0x08)) /* suppress: acceleration over threshold during latency */
			e->suppressed = 1;
	} else if (!above && e->above) { /* falling edge: a tap if it was short enough */
		e->above = 0;
		uint64_t d = now_us - e->above_start_us;
		if (d <= dur_us) {
			if (e->second == 2 && e->above_start_us <= e->first_tap_end_us + latent_us + window_us) {
				b->adxl_int_source |= INT_DOUBLE_TAP;
				b->events_double_tap++;
				e->second = 0;
			} else if (e->second == 0) {
				b->adxl_int_source |= INT_SINGLE_TAP;
				b->adxl_act_tap_status = (uint8_t)((b->adxl_act_tap_status & 0xF8) | e->above_axes);
				b->events_single_tap++;
				if (double_enabled) {
					e->second = 1;
					e->first_tap_end_us = now_us;
					e->suppressed = 0;
				}
			}
			/* a tap ending during latency without suppress is ignored */
		} else if (e->second == 2) {
			e->second = 0; /* the second event lasted longer than DUR: invalid double tap */
		}
	}

	/* free fall: all axes below THRESH_FF for at least TIME_FF */
	long ffthr = 16L * r[ADXL_THRESH_FF];
	uint64_t fftime_us = 5000ULL * r[ADXL_TIME_FF];
	int below = r[ADXL_THRESH_FF] && labs(a[0]) < ffthr && labs(a[1]) < ffthr && labs(a[2]) < ffthr;
	if (below) {
		if (!e->ff_below) {
			e->ff_below = 1;
			e->ff_start_us = now_us;
		}
		if (r[ADXL_TIME_FF] && now_us - e->ff_start_us >= fftime_us) {
			if (!(b->adxl_int_source & INT_FREE_FALL))
				b->events_free_fall++;
			b->adxl_int_source |= INT_FREE_FALL;
		}
	} else {
		e->ff_below = 0;
	}
}

static avr_cycle_count_t adxl_tick(avr_t *avr, avr_cycle_count_t when, void *param)
{
	board_t *b = param;
	chip_t *c = &b->chip[CHIP_ADXL345];
	double odr = adxl_odr(c);
	if (!(c->regs[ADXL_POWER_CTL] & 0x08)) { /* standby: no sampling; poll for MEASURE every 1 ms */
		b->adxl_timer_running = 0;
		return when + avr->frequency / 1000;
	}
	double t_s = (double)when / avr->frequency;
	b->adxl_tick++;
	long a[3];
	adxl_accel_fullres(b, t_s, odr, a);
	adxl_store_sample(b, a, t_s);
	c->last_sample = b->adxl_tick;
	c->has_sample = 1;
	adxl_engine(b, (uint64_t)(t_s * 1e6), a);
	adxl_fifo_trigger(b);
	adxl_update_int1(b);
	b->adxl_odr_hz = odr;
	/* the chip's own oscillator: its ODR is off the Nano's crystal by ppm */
	avr_cycle_count_t period = (avr_cycle_count_t)llround(avr->frequency / (odr * (1.0 + b->imp.ppm[CHIP_ADXL345] * 1e-6)));
	return when + period;
}

static void adxl_write(chip_t *c, uint8_t reg, uint8_t v)
{
	board_t *b = c->board;
	switch (reg) {
	case ADXL_DEVID: case ADXL_ACT_TAP_STATUS: case ADXL_INT_SOURCE: case ADXL_FIFO_STATUS:
		return; /* read-only */
	default:
		if (reg >= ADXL_DATAX0 && reg <= ADXL_DATAZ1)
			return;
		if (reg < 0x1D || reg > 0x39)
			return; /* reserved */
	}
	int old_mode = adxl_fifo_mode(c);
	c->regs[reg] = v;
	if (reg == ADXL_FIFO_CTL) {
		int mode = adxl_fifo_mode(c);
		if (mode != old_mode) { /* bypass: "the FIFO is not operational and, therefore, remains empty" */
			b->adxl_fifo_n = 0;
			b->adxl_fifo_trig = 0;
		}
		if (mode != FIFO_BYPASS)
			adxl_fifo_status(b);
		else
			b->adxl_int_source &= (uint8_t)~INT_WATERMARK;
	}
	if (reg == ADXL_INT_ENABLE || reg == ADXL_INT_MAP || reg == ADXL_DATA_FORMAT || reg == ADXL_FIFO_CTL)
		adxl_update_int1(b);
}

static uint8_t adxl_read(chip_t *c, uint8_t reg)
{
	board_t *b = c->board;
	if (reg >= ADXL_DATAX0 && reg <= ADXL_DATAZ1) {
		if (adxl_fifo_mode(c) == FIFO_BYPASS) {
			if (!b->adxl_popped && c->has_sample)
				adxl_note_age(b, b->adxl_data_t);
			c->data_read_sample = c->last_sample;
			b->adxl_int_source &= (uint8_t)~(INT_DATA_READY | INT_OVERRUN);
		} else if (!b->adxl_popped && b->adxl_fifo_n > 0) {
			/* the set latched for this read leaves the FIFO; the next oldest moves into the registers */
			adxl_note_age(b, b->adxl_fifo_t[0]);
			adxl_fifo_drop(b, 1);
			if (b->adxl_fifo_n)
				adxl_set_data(c, b->adxl_fifo[0]);
			b->adxl_int_source &= (uint8_t)~INT_OVERRUN;
			adxl_fifo_status(b);
		}
		b->adxl_popped = 1;
		adxl_update_int1(b);
		return c->latched[reg];
	}
	if (reg == ADXL_INT_SOURCE) {
		uint8_t v = b->adxl_int_source;
		/* reading INT_SOURCE clears the tap, activity and free-fall bits */
		b->adxl_int_source &= (uint8_t)(INT_DATA_READY | INT_WATERMARK | INT_OVERRUN);
		adxl_update_int1(b);
		return v;
	}
	if (reg == ADXL_ACT_TAP_STATUS)
		return b->adxl_act_tap_status;
	if (reg == ADXL_FIFO_STATUS) /* FIFO_TRIG, entries */
		return adxl_fifo_mode(c) == FIFO_BYPASS ? ((b->adxl_int_source & INT_DATA_READY) ? 1 : 0)
		       : (uint8_t)((b->adxl_fifo_trig ? 0x80 : 0) | b->adxl_fifo_n);
	if (reg < 0x1D && reg != ADXL_DEVID)
		return 0;
	return c->regs[reg];
}

static uint8_t adxl_next(chip_t *c, uint8_t reg) { (void)c; return (uint8_t)((reg + 1) & 0x3F); }

static void adxl_address(chip_t *c)
{
	memcpy(c->latched, c->regs, sizeof(c->regs)); /* multi-byte reads are coherent */
	c->board->adxl_popped = 0;
}

/* ---------------------------------------------------------------- ITG-3200 */

enum { ITG_WHO_AM_I = 0x00, ITG_SMPLRT_DIV = 0x15, ITG_DLPF_FS = 0x16, ITG_INT_CFG = 0x17,
       ITG_INT_STATUS = 0x1A, ITG_TEMP_OUT_H = 0x1B, ITG_GYRO_XOUT_H = 0x1D, ITG_GYRO_ZOUT_L = 0x22,
       ITG_PWR_MGM = 0x3E };

/* DLPF_CFG -> bandwidth (Hz) and internal sample rate (section 8.3, register 22) */
static const double itg_bw_hz[8] = {256, 188, 98, 42, 20, 10, 5, 256};
#define ITG_LSB_PER_DPS 14.375     /* section 3.1, FS_SEL = 3 */
#define ITG_STARTUP_S 0.050        /* section 3.1: start-up time from power on, 50 ms */
#define ITG_NOISE_DENSITY 0.03     /* section 3.1: rate noise spectral density, deg/s/sqrt(Hz) */
#define ITG_WARMUP_C 6.0           /* the die warms this much above ambient after power-on (model) */
#define ITG_WARMUP_TAU_S 90.0

static double itg_internal_hz(chip_t *c) { return (c->regs[ITG_DLPF_FS] & 7) ? 1000.0 : 8000.0; }

/* modelled die temperature, deg C: ambient 25, warming after power-on (noise mode) */
static double itg_temp_c(board_t *b, double t_s)
{
	if (!b->imp.noise)
		return 25.0;
	double since = t_s - b->itg.on_s;
	return 25.0 + ITG_WARMUP_C * (1.0 - exp(-(since > 0 ? since : 0) / ITG_WARMUP_TAU_S));
}

/* Run the internal sampling (1 or 8 kHz on the chip's own oscillator) up to now: the motion through the
 * DLPF (a 2nd-order Butterworth at the DLPF_CFG bandwidth), plus bias and noise; every SMPLRT_DIV + 1
 * internal samples the output registers take the newest value and RAW_DATA_RDY is set (section 8.2). */
static void itg_refresh(chip_t *c)
{
	board_t *b = c->board;
	itg_state_t *s = &b->itg;
	if (c->regs[ITG_PWR_MGM] & 0x40) /* SLEEP */
		return;
	double t = board_time_s(b);
	if (t < s->on_s + ITG_STARTUP_S)
		return; /* still starting up: the output registers keep their reset value */
	double fi = itg_internal_hz(c);
	double ct0 = chip_time(b, CHIP_ITG3200, s->on_s + ITG_STARTUP_S), ct = chip_time(b, CHIP_ITG3200, t);
	uint64_t K = (uint64_t)floor((ct - ct0) * fi);
	int cfg = c->regs[ITG_DLPF_FS] & 7;
	/* Butterworth biquad by the bilinear transform (prewarped) */
	double Kw = tan(M_PI * itg_bw_hz[cfg] / fi), norm = 1.0 / (1.0 + M_SQRT2 * Kw + Kw * Kw);
	double b0 = Kw * Kw * norm, b1 = 2 * b0, a1 = 2 * (Kw * Kw - 1) * norm, a2 = (1 - M_SQRT2 * Kw + Kw * Kw) * norm;
	uint64_t k = s->internal_k;
	if (!s->running || cfg != s->dlpf_cfg || K > k + (uint64_t)fi) { /* (re)start: the filter settled */
		k = K > (uint64_t)(fi / 20) ? K - (uint64_t)(fi / 20) : 0;
		s->running = 1;
		s->dlpf_cfg = cfg;
		double g[3], body[3];
		trace_interp(&b->trace->gyro, board_of_chip(b, CHIP_ITG3200, ct0 + k / fi), body);
		to_chip(b, CHIP_ITG3200, body, g);
		for (int i = 0; i < 3; i++) { /* steady state of the transposed direct form II for input x */
			double x = g[i] / ITG_LSB_PER_DPS;
			s->z1[i] = x - b0 * x;
			s->z2[i] = b0 * x - a2 * x;
			s->out[i] = x;
		}
	}
	int div = c->regs[ITG_SMPLRT_DIV] + 1, fresh = 0;
	double sigma = ITG_NOISE_DENSITY * sqrt(fi / 2.0);
	for (uint64_t j = k + 1; j <= K; j++) {
		double tb = board_of_chip(b, CHIP_ITG3200, ct0 + j / fi);
		double body[3], g[3];
		trace_interp(&b->trace->gyro, tb, body);
		to_chip(b, CHIP_ITG3200, body, g);
		double temp = itg_temp_c(b, tb);
		for (int i = 0; i < 3; i++) {
			double x = g[i] / ITG_LSB_PER_DPS;
			if (b->imp.noise)
				x += s->bias0_dps[i] + s->drift_dps_per_c[i] * (temp - 25.0) + sigma * rng_gauss(&s->rng);
			double y = b0 * x + s->z1[i];
			s->z1[i] = b1 * x - a1 * y + s->z2[i];
			s->z2[i] = b0 * x - a2 * y;
			s->out[i] = y;
		}
		if (j % (uint64_t)div == 0)
			fresh = 1;
	}
	s->internal_k = K;
	if (!fresh && c->has_sample)
		return;
	c->last_sample = K / (uint64_t)div;
	c->has_sample = 1;
	/* TEMP_OUT: -13200 LSB at 35 degC, 280 LSB/degC (section 3.1) */
	long temp = lround(-13200.0 + 280.0 * (itg_temp_c(b, t) - 35.0));
	c->regs[ITG_TEMP_OUT_H] = (uint8_t)((uint16_t)temp >> 8);
	c->regs[ITG_TEMP_OUT_H + 1] = (uint8_t)(temp & 0xFF);
	int fs = (c->regs[ITG_DLPF_FS] >> 3) & 3;
	for (int i = 0; i < 3; i++) {
		int16_t v = fs == 3 ? clip16(lround(s->out[i] * ITG_LSB_PER_DPS), -32768, 32767) : 0; /* only FS_SEL = 3 is valid */
		c->regs[ITG_GYRO_XOUT_H + 2 * i] = (uint8_t)((uint16_t)v >> 8); /* big-endian */
		c->regs[ITG_GYRO_XOUT_H + 2 * i + 1] = (uint8_t)(v & 0xFF);
	}
	c->regs[ITG_INT_STATUS] |= 0x01 | 0x04; /* RAW_DATA_RDY, ITG_RDY */
}

static void itg_power_on(chip_t *c)
{
	board_t *b = c->board;
	memset(c->regs, 0, sizeof(c->regs));
	c->regs[ITG_WHO_AM_I] = 0x68;
	c->has_sample = 0;
	b->itg.running = 0;
	b->itg.internal_k = 0;
	b->itg.on_s = board_time_s(b);
}

static void itg_write(chip_t *c, uint8_t reg, uint8_t v)
{
	if (reg == ITG_WHO_AM_I) {
		c->regs[reg] = (uint8_t)((c->regs[reg] & 0x81) | (v & 0x7E));
		return;
	}
	if (reg == ITG_SMPLRT_DIV || reg == ITG_DLPF_FS || reg == ITG_INT_CFG)
		c->regs[reg] = v;
	else if (reg == ITG_PWR_MGM) {
		if (v & 0x80) { /* H_RESET: registers to their power-on values, start-up again */
			itg_power_on(c);
			return;
		}
		if ((c->regs[reg] & 0x40) && !(v & 0x40)) { /* out of SLEEP: start-up again */
			c->board->itg.on_s = board_time_s(c->board);
			c->board->itg.running = 0;
		}
		c->regs[reg] = v;
	}
}

static uint8_t itg_read(chip_t *c, uint8_t reg)
{
	if (reg == ITG_INT_STATUS) {
		uint8_t v = c->latched[reg];
		c->regs[reg] &= (uint8_t)~0x01; /* cleared by reading the status register */
		return v;
	}
	if (reg >= ITG_TEMP_OUT_H && reg <= ITG_GYRO_ZOUT_L) {
		c->data_read_sample = c->last_sample;
		if (c->regs[ITG_INT_CFG] & 0x10) /* INT_ANYRD_2CLEAR */
			c->regs[ITG_INT_STATUS] &= (uint8_t)~0x01;
	}
	return c->latched[reg];
}

static uint8_t itg_next(chip_t *c, uint8_t reg) { (void)c; return (uint8_t)((reg + 1) & 0x3F); }

/* the sensor registers are read as a coherent set in one burst (section 8: read them in a single burst) */
static void itg_address(chip_t *c)
{
	itg_refresh(c);
	memcpy(c->latched, c->regs, sizeof(c->regs));
}

/* ---------------------------------------------------------------- HMC5883L */

enum { HMC_CRA = 0, HMC_CRB = 1, HMC_MODE = 2, HMC_DATA = 3, HMC_STATUS = 9, HMC_ID = 10 };
static const double hmc_rates[8] = {0.75, 1.5, 3, 7.5, 15, 30, 75, 75}; /* CRA DO2..DO0 (Table 5; 7 reserved) */
static const double hmc_gain_lsb_per_gauss[8] = {1370, 1090, 820, 660, 440, 390, 330, 230}; /* CRB GN (Table 9) */
#define HMC_TRACE_LSB_PER_GAUSS 1090.0 /* the trace's unit: gain 1 */
#define HMC_SINGLE_S 0.006             /* single measurement: data ~6 ms after the request ("Wait 6 ms") */
#define HMC_RDY_LOW_S 250e-6           /* RDY (and DRDY) low for 250 us around the write of new data */
#define HMC_POWER_ON_S 0.056           /* power-on: the default single measurement is ready after ~56 ms */
#define HMC_NOISE_GAUSS 0.002          /* noise floor 2 milli-gauss (standard deviation, Table 1) */
enum { HMC_STATUS_RDY = 0x01, HMC_STATUS_LOCK = 0x02 };

static double hmc_rate(chip_t *c) { return hmc_rates[(c->regs[HMC_CRA] >> 2) & 7]; }

/* One measurement completing at chip time ct: the field (or, in self-test, the bias field alone), averaged
 * over 1/2/4/8 samples (CRA MA1..MA0), at the gain, -4096 on an axis whose ADC over- or underflows. */
static void hmc_place(chip_t *c, const int16_t out[3], double ct);

static void hmc_measure(chip_t *c, double ct)
{
	board_t *b = c->board;
	hmc_state_t *s = &b->hmc;
	s->measurements++;
	double body[3], chip[3];
	trace_interp(&b->trace->mag, board_of_chip(b, CHIP_HMC5883L, ct), body);
	to_chip(b, CHIP_HMC5883L, body, chip);
	int navg = 1 << ((c->regs[HMC_CRA] >> 5) & 3);
	int bias = c->regs[HMC_CRA] & 3; /* MS1..MS0: 01 positive, 10 negative self-test bias */
	double gain = hmc_gain_lsb_per_gauss[c->regs[HMC_CRB] >> 5];
	static const double selftest_gauss[3] = {1.16, 1.16, 1.08}; /* "Self test operation" */
	int16_t out[3];
	for (int i = 0; i < 3; i++) {
		double gauss = chip[i] / HMC_TRACE_LSB_PER_GAUSS;
		if (bias == 1 || bias == 2) /* the first acquisition is subtracted from the biased one */
			gauss = bias == 1 ? selftest_gauss[i] : -selftest_gauss[i];
		if (b->imp.noise)
			gauss += HMC_NOISE_GAUSS / sqrt(navg) * rng_gauss(&s->rng);
		long v = lround(gauss * gain);
		out[i] = (v < -2048 || v > 2047) ? -4096 : (int16_t)v;
	}
	if (s->locked) { /* the lock holds the old sample: the new one waits until it opens (LOCK, register 9) */
		s->dropped_locked++;
		memcpy(s->pending_out, out, sizeof out);
		s->pending = 1;
		s->pending_ct = ct;
		return;
	}
	hmc_place(c, out, ct);
}

/* The chip writes a measurement into the data output registers at chip time ct. */
static void hmc_place(chip_t *c, const int16_t out[3], double ct)
{
	hmc_state_t *s = &c->board->hmc;
	/* output order X, Z, Y; big-endian */
	const int order[3] = {0, 2, 1};
	for (int i = 0; i < 3; i++) {
		c->regs[HMC_DATA + 2 * i] = (uint8_t)((uint16_t)out[order[i]] >> 8);
		c->regs[HMC_DATA + 2 * i + 1] = (uint8_t)(out[order[i]] & 0xFF);
	}
	/* RDY clears when the chip starts writing and stays clear 250 us; it is set when all six are written */
	c->regs[HMC_STATUS] &= (uint8_t)~HMC_STATUS_RDY;
	s->rdy_clear_until_s = ct + HMC_RDY_LOW_S;
	c->last_sample++;
	c->has_sample = 1;
}

/* Complete the measurements due by now (continuous: every 1/fDO; single: once, then idle). */
static void hmc_refresh(chip_t *c)
{
	board_t *b = c->board;
	hmc_state_t *s = &b->hmc;
	double ct = chip_time(b, CHIP_HMC5883L, board_time_s(b));
	int mode = c->regs[HMC_MODE] & 3;
	if (s->next_done_s >= 0 && s->next_done_s <= ct) {
		if (mode == 0) {
			double period = 1.0 / hmc_rate(c);
			double n = floor((ct - s->next_done_s) / period); /* measurements missed by a lazy refresh */
			s->next_done_s += n * period;
			hmc_measure(c, s->next_done_s);
			s->next_done_s += period;
		} else {
			hmc_measure(c, s->next_done_s);
			s->next_done_s = -1;
			if (mode == 1) /* single: back to idle (the mode register returns to the idle bits) */
				c->regs[HMC_MODE] = (uint8_t)((c->regs[HMC_MODE] & ~3) | 3);
		}
	}
	if (!(c->regs[HMC_STATUS] & HMC_STATUS_RDY) && c->has_sample && s->rdy_clear_until_s >= 0 &&
	    ct >= s->rdy_clear_until_s) {
		c->regs[HMC_STATUS] |= HMC_STATUS_RDY;
		s->rdy_clear_until_s = -1;
	}
	c->regs[HMC_STATUS] = (uint8_t)((c->regs[HMC_STATUS] & ~HMC_STATUS_LOCK) | (s->locked ? HMC_STATUS_LOCK : 0));
}

/* DRDY (pin description: "Low for 250 usec when data is placed in the data output registers", pulled up
 * otherwise). Only with a pin for it (--drdy-pin): then the chip's events run on a cycle timer, so the pin
 * moves at the measurement's time and not only when the bus next reads the chip. */
static avr_cycle_count_t hmc_drdy_timer(avr_t *avr, avr_cycle_count_t when, void *param);

static void hmc_drdy_arm(chip_t *c)
{
	board_t *b = c->board;
	if (!b->drdy_pin)
		return;
	hmc_state_t *s = &b->hmc;
	double ct = chip_time(b, CHIP_HMC5883L, board_time_s(b));
	int low = s->rdy_clear_until_s >= 0 && ct < s->rdy_clear_until_s;
	if (low != b->drdy_low) {
		b->drdy_low = low;
		avr_raise_irq(b->drdy_pin, low ? 0 : 1);
	}
	double next = s->rdy_clear_until_s > ct ? s->rdy_clear_until_s : -1;
	if (s->next_done_s >= 0 && (next < 0 || s->next_done_s < next))
		next = s->next_done_s;
	avr_cycle_timer_cancel(b->avr, hmc_drdy_timer, c);
	if (next >= 0) {
		avr_cycle_count_t at = (avr_cycle_count_t)ceil(board_of_chip(b, CHIP_HMC5883L, next) * b->avr->frequency);
		avr_cycle_timer_register(b->avr, at > b->avr->cycle ? at - b->avr->cycle : 1, hmc_drdy_timer, c);
	}
}

static avr_cycle_count_t hmc_drdy_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
	(void)avr; (void)when;
	chip_t *c = param;
	hmc_refresh(c);
	hmc_drdy_arm(c);
	return 0;
}

static void hmc_unlock(board_t *b)
{
	b->hmc.locked = 0;
	b->hmc.read_mask = 0;
}

/* All six bytes read: the lock opens and a measurement that waited for it is placed now. */
static void hmc_unlock_by_read(chip_t *c)
{
	board_t *b = c->board;
	hmc_unlock(b);
	if (b->hmc.pending) {
		b->hmc.pending = 0;
		hmc_place(c, b->hmc.pending_out, chip_time(b, CHIP_HMC5883L, board_time_s(b)));
	}
}

/* A write to the mode register or CRA starts the measurements again: continuous gives its first after
 * 2/fDO, single after ~6 ms; idle stops. */
static void hmc_schedule(chip_t *c)
{
	board_t *b = c->board;
	double ct = chip_time(b, CHIP_HMC5883L, board_time_s(b));
	int mode = c->regs[HMC_MODE] & 3;
	b->hmc.next_done_s = mode == 0 ? ct + 2.0 / hmc_rate(c) : mode == 1 ? ct + HMC_SINGLE_S : -1;
}

static void hmc_power_on(chip_t *c)
{
	board_t *b = c->board;
	memset(c->regs, 0, sizeof(c->regs));
	c->regs[HMC_CRA] = 0x10;
	c->regs[HMC_CRB] = 0x20;
	c->regs[HMC_MODE] = 0x01;
	c->regs[HMC_ID] = 'H';
	c->regs[HMC_ID + 1] = '4';
	c->regs[HMC_ID + 2] = '3';
	c->has_sample = 0;
	c->last_sample = 0;
	hmc_unlock(b);
	b->hmc.pending = 0;
	b->hmc.rdy_clear_until_s = -1;
	b->hmc.next_done_s = chip_time(b, CHIP_HMC5883L, board_time_s(b)) + HMC_POWER_ON_S;
}

static void hmc_write(chip_t *c, uint8_t reg, uint8_t v)
{
	hmc_refresh(c);
	if (reg > HMC_MODE)
		return;
	c->regs[reg] = v;
	if (reg == HMC_MODE || reg == HMC_CRA) { /* both unlock the data output registers (a waiting sample is lost) */
		hmc_unlock(c->board);
		c->board->hmc.pending = 0;
		hmc_schedule(c);
	}
	hmc_drdy_arm(c);
}

static uint8_t hmc_read(chip_t *c, uint8_t reg)
{
	hmc_refresh(c); /* a measurement may complete in the middle of a read: the lock is what keeps it whole */
	board_t *b = c->board;
	if (reg > 12)
		return 0;
	uint8_t v = c->regs[reg];
	if (reg >= HMC_DATA && reg < HMC_STATUS) {
		b->hmc.read_mask |= (uint8_t)(1 << (reg - HMC_DATA));
		if (b->hmc.read_mask == 0x3F) {
			c->data_read_sample = c->last_sample;
			hmc_unlock_by_read(c);
			/* single-measurement mode: RDY stays high until the data output register is read */
			if ((c->regs[HMC_MODE] & 3) != 0)
				c->regs[HMC_STATUS] &= (uint8_t)~HMC_STATUS_RDY;
		} else
			b->hmc.locked = 1;
	} else if (reg == HMC_MODE)
		b->hmc.locked = 1; /* reading the mode register locks the data output registers */
	if (reg == HMC_STATUS)
		v = (uint8_t)((v & ~HMC_STATUS_LOCK) | (b->hmc.locked ? HMC_STATUS_LOCK : 0));
	hmc_drdy_arm(c); /* the lock may have opened and placed a waiting measurement */
	return v;
}

static uint8_t hmc_next(chip_t *c, uint8_t reg)
{
	(void)c;
	if (reg == 8)
		return 3; /* the pointer returns to X MSB after the six data registers */
	if (reg >= 12)
		return 0;
	return (uint8_t)(reg + 1);
}

static void hmc_address(chip_t *c) { hmc_refresh(c); }

/* ---------------------------------------------------------------- QMC5883L */

enum { QMC_DATA = 0x00, QMC_STATUS = 0x06, QMC_TOUT = 0x07, QMC_CR1 = 0x09, QMC_CR2 = 0x0A, QMC_SETRESET = 0x0B,
       QMC_ID = 0x0D };
enum { QMC_DRDY = 0x01, QMC_OVL = 0x02, QMC_DOR = 0x04 };
static const double qmc_odr_hz[4] = {10, 50, 100, 200};      /* CR1 ODR (section 9.2.2) */
static const double qmc_lsb_per_gauss[4] = {12000, 3000, 12000, 3000}; /* RNG 2 G / 8 G (section 2.1) */

static void qmc_power_on(chip_t *c)
{
	memset(c->regs, 0, sizeof(c->regs));
	c->regs[QMC_ID] = 0xFF;
	c->has_sample = 0;
	c->board->qmc.has = 0;
	c->board->qmc.on_s = board_time_s(c->board);
}

static void qmc_refresh(chip_t *c)
{
	board_t *b = c->board;
	qmc_state_t *s = &b->qmc;
	if ((c->regs[QMC_CR1] & 3) != 1) /* standby */
		return;
	double odr = qmc_odr_hz[(c->regs[QMC_CR1] >> 2) & 3];
	double ct = chip_time(b, CHIP_HMC5883L, board_time_s(b)) - chip_time(b, CHIP_HMC5883L, s->on_s);
	if (ct < 1.0 / odr)
		return;
	uint64_t k = (uint64_t)floor(ct * odr);
	if (s->has && k == s->k)
		return;
	/* DOR: a sample was skipped (the one before was never read), also between two lazy refreshes */
	if (s->has ? ((c->regs[QMC_STATUS] & QMC_DRDY) || k > s->k + 1) : k >= 2)
		c->regs[QMC_STATUS] |= QMC_DOR;
	s->k = k;
	s->has = 1;
	double body[3], chip[3];
	trace_interp(&b->trace->mag, board_of_chip(b, CHIP_HMC5883L, chip_time(b, CHIP_HMC5883L, s->on_s) + k / odr), body);
	to_chip(b, CHIP_HMC5883L, body, chip);
	double scale = qmc_lsb_per_gauss[(c->regs[QMC_CR1] >> 4) & 3];
	double range = ((c->regs[QMC_CR1] >> 4) & 1) ? 8.0 : 2.0;
	int ovl = 0;
	for (int i = 0; i < 3; i++) {
		double gauss = chip[i] / HMC_TRACE_LSB_PER_GAUSS;
		if (b->imp.noise)
			gauss += HMC_NOISE_GAUSS * rng_gauss(&s->rng);
		if (fabs(gauss) > range)
			ovl = 1;
		int16_t v = clip16(lround(gauss * scale), -32768, 32767);
		c->regs[QMC_DATA + 2 * i] = (uint8_t)(v & 0xFF); /* little-endian, X, Y, Z */
		c->regs[QMC_DATA + 2 * i + 1] = (uint8_t)((uint16_t)v >> 8);
	}
	int16_t temp = (int16_t)lround(100.0 * (itg_temp_c(b, board_time_s(b)) - 25.0)); /* 100 LSB/degC, relative */
	c->regs[QMC_TOUT] = (uint8_t)(temp & 0xFF);
	c->regs[QMC_TOUT + 1] = (uint8_t)((uint16_t)temp >> 8);
	c->regs[QMC_STATUS] = (uint8_t)((c->regs[QMC_STATUS] & ~QMC_OVL) | QMC_DRDY | (ovl ? QMC_OVL : 0));
	c->last_sample = k;
	c->has_sample = 1;
}

static void qmc_write(chip_t *c, uint8_t reg, uint8_t v)
{
	if (reg == QMC_CR2 && (v & 0x80)) { /* SOFT_RST: all registers to their defaults */
		qmc_power_on(c);
		return;
	}
	if (reg == QMC_CR1 || reg == QMC_CR2 || reg == QMC_SETRESET) {
		if (reg == QMC_CR1 && (v & 3) == 1 && (c->regs[QMC_CR1] & 3) != 1) { /* standby -> continuous */
			c->board->qmc.on_s = board_time_s(c->board);
			c->board->qmc.has = 0;
		}
		c->regs[reg] = v;
	}
}

static uint8_t qmc_read(chip_t *c, uint8_t reg)
{
	if (reg <= QMC_DATA + 5) /* reading any data register clears DRDY and DOR */
		c->regs[QMC_STATUS] &= (uint8_t)~(QMC_DRDY | QMC_DOR);
	if (reg == QMC_STATUS) /* the status as it is now (the data are read as latched at the START) */
		return c->regs[reg];
	if (reg <= QMC_ID)
		return c->latched[reg];
	return 0;
}

static uint8_t qmc_next(chip_t *c, uint8_t reg)
{
	if ((c->regs[QMC_CR2] & 0x40) && reg == QMC_STATUS) /* ROL_PNT: the pointer rolls 06H -> 00H */
		return QMC_DATA;
	return (uint8_t)((reg + 1) & 0x3F);
}

static void qmc_address(chip_t *c)
{
	qmc_refresh(c);
	memcpy(c->latched, c->regs, sizeof(c->regs));
}

/* ---------------------------------------------------------------- the bus */

static void twi_send(board_t *b, uint8_t msg, uint8_t addr, uint8_t data)
{
	avr_raise_irq(b->irq + TWI_IRQ_INPUT, avr_twi_irq_msg(msg, addr, data));
}

/* --i2c-real-timing: one cycle after the AVR's TWI started a step (it registers its completion timer right
 * after raising the message we hook), move the completion to 9 SCL periods after the step started,
 * SCL = F_CPU / (16 + 2 TWBR 4^TWPS), instead of simavr's 1 us. */
static avr_cycle_count_t twi_fixup(avr_t *avr, avr_cycle_count_t when, void *param)
{
	board_t *b = param;
	avr_twi_t *twi = b->twi;
	(void)twi;
	if (b->real_timing || b->stretch_cycles) {
		uint8_t twbr = avr->data[0xB8], twps = avr->data[0xB9] & 3;
		avr_cycle_count_t scl = 16 + 2ULL * twbr * (1ULL << (2 * twps));
		avr_cycle_count_t want = b->msg_cycle + (b->real_timing ? 9 * scl : 0) + b->stretch_cycles;
		if (b->stretch_cycles) { /* a slave held SCL low this long in this byte (clock stretching) */
			b->clock_stretches++;
			if (b->on_fault)
				b->on_fault(b, "clock_stretch", b->cur_chip);
			b->stretch_cycles = 0;
		}
		for (avr_cycle_timer_slot_p s = avr->cycle_timers.timer; s; s = s->next) {
			if (s->param == b->twi) {
				if (s->when < want)
					avr_cycle_timer_register(avr, want - avr->cycle, s->timer, b->twi);
				break;
			}
		}
	}
	return 0;
}

static void twi_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	board_t *b = param;
	avr_twi_msg_irq_t v;
	v.u.v = value;
	uint8_t msg = v.u.twi.msg;
	if (b->twi && (msg & (TWI_COND_START | TWI_COND_WRITE | TWI_COND_READ))) {
		b->msg_cycle = b->avr->cycle;
		b->sla_w_pending = (msg & TWI_COND_START) && !(v.u.twi.addr & 1) && b->fix_status;
		if (b->real_timing || b->stretch_cycles)
			avr_cycle_timer_register(b->avr, 1, twi_fixup, b);
	}

	if (msg & TWI_COND_STOP) {
		if (b->cur_chip >= 0)
			b->chip[b->cur_chip].selected = 0;
		b->cur_chip = -1;
		b->bus_busy = 0;
	}
	if (msg & TWI_COND_START) {
		uint8_t addr7 = v.u.twi.addr >> 1;
		int read = v.u.twi.addr & 1;
		if (!b->bus_busy)
			b->transactions++;
		if (b->start_armed) {
			b->start_armed = 0;
			b->first_start_cycle = b->avr->cycle;
		}
		b->bus_busy = 1;
		b->starts++;
		if (b->cur_chip >= 0)
			b->chip[b->cur_chip].selected = 0;
		b->cur_chip = -1;
		for (int i = 0; i < CHIP_COUNT; i++) {
			chip_t *c = &b->chip[i];
			if (c->addr7 != addr7)
				continue;
			c->addressed++;
			if (c->nack || c->glitch_nack) {
				c->nacked++;
				if (c->glitch_nack) {
					c->glitch_nack = 0;
					b->glitch_nacks++;
					if (b->on_fault)
						b->on_fault(b, "glitch_nack", i);
				}
				break;
			}
			c->selected = read ? 2 : 1;
			c->index = 0;
			b->cur_chip = i;
			if (c->on_address)
				c->on_address(c);
			twi_send(b, TWI_COND_ACK, v.u.twi.addr, 1);
			break;
		}
		if (b->cur_chip < 0) {
			b->addr_nacks++;
			b->i2c_errors++;
		}
		if (b->verbose > 1)
			fprintf(b->log, "[%.6f] i2c START 0x%02x %s -> %s\n", board_time_s(b), addr7, read ? "R" : "W",
				b->cur_chip >= 0 ? "ACK" : "NACK");
		return;
	}
	/* No chip selected: the address was refused. A master that read on would read 0xFF as well (nothing drives
	 * SDA); it is left unanswered because no master run here reads after a refused address: the firmware
	 * (avr_twi.cpp, startAndAddress) and Wire stop at the NACK. Counted with a build that logs such reads: 0 in
	 * a whole guided calibration on gy85 (tests/e2e/test_calibrate_sim.py), which passes with them answered
	 * 0xFF too, so the two failures of that test with 85ace39's board were not this answer. */
	if (b->cur_chip < 0)
		return;
	chip_t *c = &b->chip[b->cur_chip];
	/* A chip that goes away in the middle of a read drives SDA no more: the pull-ups make every bit 1, so the
	 * master reads 0xFF (I2C-bus specification UM10204, 3.1.3 "Data validity" and 3.1.6 "Acknowledge": the
	 * receiver, here the master, drives the acknowledge, so its TWI reports "data received" all the same). The
	 * first byte it misses is answered 0xFF here; simavr's TWDR then holds 0xFF for the rest of the read (not
	 * answering at all left it holding the last byte the chip sent: a gyro read cut by a NACK in the soak read
	 * 0x4F4F, 1412 deg/s, on two axes). */
	if (c->nack) { /* went away in the middle of a transaction */
		b->i2c_errors++;
		b->cur_chip = -1;
		if (msg & TWI_COND_READ)
			twi_send(b, TWI_COND_READ, v.u.twi.addr, 0xFF);
		return;
	}
	if (msg & TWI_COND_WRITE) {
		twi_send(b, TWI_COND_ACK, v.u.twi.addr, 1);
		if (c->index == 0)
			c->ptr = v.u.twi.data & 0x3F;
		else {
			c->on_write(c, c->ptr, v.u.twi.data);
			c->ptr = c->next_ptr(c, c->ptr);
		}
		if (b->verbose > 1)
			fprintf(b->log, "[%.6f] i2c %s W 0x%02x\n", board_time_s(b), c->name, v.u.twi.data);
		c->index++;
	}
	if (msg & TWI_COND_READ) {
		uint8_t data = c->on_read(c, c->ptr);
		c->ptr = c->next_ptr(c, c->ptr);
		twi_send(b, TWI_COND_READ, v.u.twi.addr, data);
		if (b->reset_on_read) {
			b->reset_on_read = 0;
			b->reset_pending = 1;
		}
		if (b->verbose > 1)
			fprintf(b->log, "[%.6f] i2c %s R 0x%02x\n", board_time_s(b), c->name, data);
	}
}

/* simavr 1.6 completes an acknowledged SLA+W with status 0x28 (data ACK) instead of 0x18, and a refused
 * one with 0x30 instead of 0x20; a driver that checks the datasheet's codes (as a polling driver does)
 * then gives up. The status is set through this IRQ right after TWSR is written: put the real code there. */
static void twi_status_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	board_t *b = param;
	if (b->fix_status && b->sla_w_pending && (value == 0x28 || value == 0x30)) {
		uint8_t fixed = value == 0x28 ? 0x18 : 0x20;
		b->avr->data[0xB9] = (uint8_t)((b->avr->data[0xB9] & 0x07) | fixed); /* TWSR */
		if (b->verbose > 2)
			fprintf(b->log, "[%.6f] twi status 0x%02x after SLA+W reported as 0x%02x\n", board_time_s(b), value, fixed);
		value = fixed;
	}
	b->sla_w_pending = 0;
	if (b->verbose > 2)
		fprintf(b->log, "[%.6f] twi status 0x%02x (TWCR 0x%02x)\n", board_time_s(b), value, b->avr->data[0xBC]);
}

/* simavr 1.6 stores the TWINT bit the program writes to TWCR as it is, so writing 1 to clear TWINT
 * leaves it set, and a polling driver sees the previous step's completion (and status) at once: the
 * "one step stale" status. The real TWI clears TWINT on that write. This runs after simavr's own TWCR
 * handler (which has already taken the write of 1 as "cleared" and started the step): clear the bit. */
static void twcr_write_hook(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
	board_t *b = param;
	if (b->fix_status && (v & 0x80))
		avr->data[addr] &= (uint8_t)~0x80;
}

static const char *irq_names[2] = {"8<sphere.twi.in", "32>sphere.twi.out"};

static void adxl_power_on(chip_t *c)
{
	memset(c->regs, 0, sizeof(c->regs));
	c->regs[ADXL_DEVID] = 0xE5;
	c->regs[ADXL_BW_RATE] = 0x0A;
	c->has_sample = 0;
	board_t *b = c->board;
	b->adxl_int_source = 0;
	b->adxl_fifo_n = 0;
	b->adxl_fifo_trig = 0;
	memset(&b->tap, 0, sizeof b->tap);
}

static void chip_power_on(board_t *b, int i)
{
	chip_t *c = &b->chip[i];
	c->holds_sda = 0;
	c->glitch_nack = 0;
	c->selected = 0;
	if (i == CHIP_ADXL345) adxl_power_on(c);
	else if (i == CHIP_ITG3200) itg_power_on(c);
	else if (b->variant->mag_kind == MAG_QMC5883L) qmc_power_on(c);
	else hmc_power_on(c);
}

void board_restart_timers(board_t *b)
{
	avr_cycle_timer_cancel(b->avr, adxl_tick, b);
	avr_cycle_timer_register(b->avr, b->avr->frequency / 1000, adxl_tick, b);
	if (b->variant->mag_kind == MAG_HMC5883L)
		hmc_drdy_arm(&b->chip[CHIP_HMC5883L]);
}

void board_wire_drdy(board_t *b, avr_irq_t *pin)
{
	b->drdy_pin = pin;
	b->drdy_low = 0;
	avr_raise_irq(pin, 1);
	if (b->variant->mag_kind == MAG_HMC5883L)
		hmc_drdy_arm(&b->chip[CHIP_HMC5883L]);
}

void board_power_cycle(board_t *b)
{
	b->power_on_s = board_time_s(b);
	for (int i = 0; i < CHIP_COUNT; i++)
		chip_power_on(b, i);
	b->bus_busy = 0;
	b->cur_chip = -1;
	adxl_update_int1(b);
	board_sda_update(b);
	board_restart_timers(b);
}

void board_avr_reset(board_t *b)
{
	b->adxl_age_pending = 1; /* the program starts again: its first accelerometer read is noted */
	/* a slave in the middle of sending a byte keeps driving SDA until the master clocks the byte out */
	if (b->bus_busy && b->cur_chip >= 0 && b->chip[b->cur_chip].selected == 2) {
		b->chip[b->cur_chip].holds_sda = 1 + (int)(rng_uniform(&b->itg.rng) * 9); /* clocks still needed: 1..9 */
		b->sda_held_events++;
	}
	board_sda_update(b);
	if (b->cur_chip >= 0)
		b->chip[b->cur_chip].selected = 0;
	b->bus_busy = 0;
	b->cur_chip = -1;
}

int board_sda_held(board_t *b)
{
	for (int i = 0; i < CHIP_COUNT; i++)
		if (b->chip[i].holds_sda)
			return 1;
	return 0;
}

/* SDA (PC4) as the AVR reads it in PINC: low while a chip holds it (the pull-ups make it high otherwise) */
void board_sda_update(board_t *b)
{
	int low = board_sda_held(b);
	if (low != b->sda_pin_low) {
		b->sda_pin_low = low;
		avr_raise_irq(b->sda_pin, low ? 0 : 1);
	}
	/* simavr's port raises the same pin IRQ with the PORT value on every PORTC write (the pull-up), which
	 * would read as SDA high: keep the PIN bit as the bus has it */
	if (low)
		b->avr->data[0x26] &= (uint8_t)~0x10;
	else
		b->avr->data[0x26] |= 0x10;
}

static int scl_level = 1;
static void scl_io_hook(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param);
void board_scl_level(board_t *b, int level)
{
	if (level && !scl_level) /* a rising edge clocks one bit out of the held byte */
		for (int i = 0; i < CHIP_COUNT; i++)
			if (b->chip[i].holds_sda && --b->chip[i].holds_sda == 0) {
				if (b->verbose)
					fprintf(b->log, "[%.6f] %s releases SDA\n", board_time_s(b), b->chip[i].name);
				if (b->on_fault)
					b->on_fault(b, "sda_released", i);
			}
	scl_level = level;
	board_sda_update(b);
}

/* SCL as the program drives PC5 while the TWI is off (open drain: low when DDR is output and PORT low).
 * Runs after the port's own handler has stored the value. */
static void scl_io_hook(struct avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)addr; (void)v;
	board_t *b = param;
	board_sda_update(b);
	if (avr->data[0xBC] & 0x04) /* TWEN: the TWI owns the pins */
		return;
	int low = (avr->data[0x27] & 0x20) && !(avr->data[0x28] & 0x20);
	if (b->verbose > 2)
		fprintf(b->log, "[%.6f] SCL %s (DDRC %02x PORTC %02x)\n", board_time_s(b), low ? "low" : "high", avr->data[0x27], avr->data[0x28]);
	board_scl_level(b, !low);
}

static void chip_setup(chip_t *c, const char *name, uint8_t addr7, void (*on_write)(chip_t *, uint8_t, uint8_t),
                       uint8_t (*on_read)(chip_t *, uint8_t), uint8_t (*next_ptr)(chip_t *, uint8_t),
                       void (*on_address)(chip_t *))
{
	c->name = name;
	c->addr7 = addr7;
	c->on_write = on_write;
	c->on_read = on_read;
	c->next_ptr = next_ptr;
	c->on_address = on_address;
}

void board_init(board_t *b, avr_t *avr, trace_t *trace, int verbose, const board_variant_t *variant,
                const imperfections_t *imp)
{
	memset(b, 0, sizeof(*b));
	b->avr = avr;
	b->trace = trace;
	b->verbose = verbose;
	b->log = stderr;
	b->cur_chip = -1;
	b->variant = variant ? variant : &board_variants[0];
	if (imp)
		b->imp = *imp;
	b->adxl_rng = rng_seed(b->imp.seed, 1);
	b->itg.rng = rng_seed(b->imp.seed, 2);
	b->hmc.rng = b->qmc.rng = rng_seed(b->imp.seed, 3);
	if (b->imp.noise) { /* turn-on offsets, within the datasheets' limits (README: typical, not worst case) */
		uint64_t r = rng_seed(b->imp.seed, 4);
		static const double adxl_sigma_lsb[3] = {5.0, 5.0, 8.0}; /* ~20/30 mg; limits +-150/+-250 mg */
		for (int i = 0; i < 3; i++) {
			b->adxl_offset_lsb[i] = adxl_sigma_lsb[i] * rng_gauss(&r);
			b->itg.bias0_dps[i] = 1.5 * rng_gauss(&r);         /* ZRO: limit +-40 deg/s */
			b->itg.drift_dps_per_c[i] = 0.05 * rng_gauss(&r);  /* ZRO over temperature: +-40 deg/s over 125 C */
		}
	}

	chip_setup(&b->chip[CHIP_ADXL345], "adxl345", 0x53, adxl_write, adxl_read, adxl_next, adxl_address);
	b->adxl_age_pending = 1; /* the program's first accelerometer read after power-up is noted */
	chip_setup(&b->chip[CHIP_ITG3200], "itg3200", 0x68, itg_write, itg_read, itg_next, itg_address);
	if (b->variant->mag_kind == MAG_QMC5883L)
		chip_setup(&b->chip[CHIP_HMC5883L], "qmc5883l", 0x0D, qmc_write, qmc_read, qmc_next, qmc_address);
	else
		chip_setup(&b->chip[CHIP_HMC5883L], "hmc5883l", 0x1E, hmc_write, hmc_read, hmc_next, hmc_address);

	for (int i = 0; i < CHIP_COUNT; i++)
		b->chip[i].board = b;
	for (int i = 0; i < CHIP_COUNT; i++)
		chip_power_on(b, i);


	b->irq = avr_alloc_irq(&avr->irq_pool, 0, 2, irq_names);
	avr_irq_register_notify(b->irq + TWI_IRQ_OUTPUT, twi_hook, b);
	avr_connect_irq(b->irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
	avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), b->irq + TWI_IRQ_OUTPUT);

	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_STATUS), twi_status_hook, b);
	avr_register_io_write(avr, 0xBC, twcr_write_hook, b); /* TWCR */
	avr_register_io_write(avr, 0x27, scl_io_hook, b);     /* DDRC: SCL is PC5 */
	avr_register_io_write(avr, 0x28, scl_io_hook, b);     /* PORTC */

	b->sda_pin = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('C'), 4);
	b->int1_pin = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
	b->int1_level = -1;
	adxl_update_int1(b);
	avr_cycle_timer_register(avr, avr->frequency / 1000, adxl_tick, b);
}
