/*
 * sensors.c - register-level models of the ADXL345, ITG-3200 and HMC5883L on simavr's TWI bus,
 * with the ADXL345's tap, double-tap and free-fall engine, fed by a recorded motion trace.
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

/* ---------------------------------------------------------------- common */

double board_time_s(board_t *b) { return (double)b->avr->cycle / (double)b->avr->frequency; }

static int16_t clip16(long v, long lo, long hi) { return (int16_t)(v < lo ? lo : v > hi ? hi : v); }

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

/* Acceleration with the offset registers applied, full-resolution LSB (3.9 mg), unsaturated. */
static void adxl_accel_fullres(board_t *b, double t_s, long out[3])
{
	const int16_t *a = trace_at(&b->trace->accel, t_s);
	for (int i = 0; i < 3; i++)
		out[i] = a[i] + 4L * (int8_t)b->chip[CHIP_ADXL345].regs[ADXL_OFSX + i]; /* OFS: 15.6 mg/LSB */
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

static void adxl_store_sample(board_t *b, double t_s)
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	long a[3];
	adxl_accel_fullres(b, t_s, a);
	uint8_t fmt = c->regs[ADXL_DATA_FORMAT];
	int range = fmt & 3;
	for (int i = 0; i < 3; i++) {
		int16_t v;
		if (fmt & 0x08) /* FULL_RES: 3.9 mg/LSB, 10 to 13 bits */
			v = clip16(a[i], -(512L << range), (512L << range) - 1);
		else /* 10 bits, scale 256 >> range LSB/g */
			v = clip16(a[i] >> range, -512, 511);
		c->regs[ADXL_DATAX0 + 2 * i] = (uint8_t)(v & 0xFF);
		c->regs[ADXL_DATAX0 + 2 * i + 1] = (uint8_t)((uint16_t)v >> 8);
	}
}

/* Tap and free-fall engine on one output-data-rate sample (datasheet rev. E, figures 37-39). */
static void adxl_engine(board_t *b, uint64_t now_us, double t_s)
{
	chip_t *c = &b->chip[CHIP_ADXL345];
	tap_engine_t *e = &b->tap;
	long a[3];
	adxl_accel_fullres(b, t_s, a);
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
	if (c->has_sample && c->data_read_sample != c->last_sample && (b->adxl_int_source & INT_DATA_READY))
		b->adxl_int_source |= INT_OVERRUN;
	c->last_sample = b->adxl_tick;
	c->has_sample = 1;
	adxl_store_sample(b, t_s);
	b->adxl_int_source |= INT_DATA_READY;
	adxl_engine(b, (uint64_t)(t_s * 1e6), t_s);
	adxl_update_int1(b);
	b->adxl_odr_hz = odr;
	avr_cycle_count_t period = (avr_cycle_count_t)llround(avr->frequency / odr);
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
	c->regs[reg] = v;
	if (reg == ADXL_INT_ENABLE || reg == ADXL_INT_MAP || reg == ADXL_DATA_FORMAT)
		adxl_update_int1(b);
}

static uint8_t adxl_read(chip_t *c, uint8_t reg)
{
	board_t *b = c->board;
	if (reg >= ADXL_DATAX0 && reg <= ADXL_DATAZ1) {
		c->data_read_sample = c->last_sample;
		b->adxl_int_source &= (uint8_t)~(INT_DATA_READY | INT_OVERRUN);
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
	if (reg == ADXL_FIFO_STATUS)
		return (b->adxl_int_source & INT_DATA_READY) ? 1 : 0;
	if (reg < 0x1D && reg != ADXL_DEVID)
		return 0;
	return c->regs[reg];
}

static uint8_t adxl_next(chip_t *c, uint8_t reg) { (void)c; return (uint8_t)((reg + 1) & 0x3F); }

static void adxl_address(chip_t *c)
{
	memcpy(c->latched, c->regs, sizeof(c->regs)); /* multi-byte reads are coherent */
}

/* ---------------------------------------------------------------- ITG-3200 */

enum { ITG_WHO_AM_I = 0x00, ITG_SMPLRT_DIV = 0x15, ITG_DLPF_FS = 0x16, ITG_INT_CFG = 0x17,
       ITG_INT_STATUS = 0x1A, ITG_TEMP_OUT_H = 0x1B, ITG_GYRO_XOUT_H = 0x1D, ITG_GYRO_ZOUT_L = 0x22,
       ITG_PWR_MGM = 0x3E };

static double itg_rate(chip_t *c)
{
	double internal = (c->regs[ITG_DLPF_FS] & 7) ? 1000.0 : 8000.0;
	return internal / (c->regs[ITG_SMPLRT_DIV] + 1.0);
}

static void itg_refresh(chip_t *c)
{
	board_t *b = c->board;
	if (c->regs[ITG_PWR_MGM] & 0x40) /* SLEEP */
		return;
	double rate = itg_rate(c), t = board_time_s(b);
	uint64_t k = (uint64_t)floor(t * rate);
	if (c->has_sample && k == c->last_sample)
		return;
	c->last_sample = k;
	c->has_sample = 1;
	const int16_t *g = trace_at(&b->trace->gyro, k / rate);
	int fs = (c->regs[ITG_DLPF_FS] >> 3) & 3;
	int16_t temp = -13200 + 280 * (25 - 35); /* 25 degC */
	c->regs[ITG_TEMP_OUT_H] = (uint8_t)((uint16_t)temp >> 8);
	c->regs[ITG_TEMP_OUT_H + 1] = (uint8_t)(temp & 0xFF);
	for (int i = 0; i < 3; i++) {
		int16_t v = fs == 3 ? g[i] : 0; /* only FS_SEL = 3 is a valid setting */
		c->regs[ITG_GYRO_XOUT_H + 2 * i] = (uint8_t)((uint16_t)v >> 8); /* big-endian */
		c->regs[ITG_GYRO_XOUT_H + 2 * i + 1] = (uint8_t)(v & 0xFF);
	}
	c->regs[ITG_INT_STATUS] |= 0x01 | 0x04; /* RAW_DATA_RDY, ITG_RDY */
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
		if (v & 0x80) { /* H_RESET */
			memset(c->regs, 0, sizeof(c->regs));
			c->regs[ITG_WHO_AM_I] = 0x68;
			c->has_sample = 0;
			return;
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

static void itg_address(chip_t *c)
{
	itg_refresh(c);
	memcpy(c->latched, c->regs, sizeof(c->regs));
}

/* ---------------------------------------------------------------- HMC5883L */

enum { HMC_CRA = 0, HMC_CRB = 1, HMC_MODE = 2, HMC_DATA = 3, HMC_STATUS = 9, HMC_ID = 10 };
static const double hmc_rates[8] = {0.75, 1.5, 3, 7.5, 15, 30, 75, 75};
static const double hmc_gain_lsb_per_gauss[8] = {1370, 1090, 820, 660, 440, 390, 330, 230};

static void hmc_store(chip_t *c, double t_s)
{
	board_t *b = c->board;
	const int16_t *m = trace_at(&b->trace->mag, t_s);
	double g = hmc_gain_lsb_per_gauss[c->regs[HMC_CRB] >> 5] / 1090.0;
	int16_t out[3];
	for (int i = 0; i < 3; i++) {
		if (m[i] == -4096) { out[i] = -4096; continue; }
		long v = lround(m[i] * g);
		out[i] = (v < -2048 || v > 2047) ? -4096 : (int16_t)v;
	}
	/* output order X, Z, Y; big-endian */
	const int order[3] = {0, 2, 1};
	for (int i = 0; i < 3; i++) {
		c->regs[HMC_DATA + 2 * i] = (uint8_t)((uint16_t)out[order[i]] >> 8);
		c->regs[HMC_DATA + 2 * i + 1] = (uint8_t)(out[order[i]] & 0xFF);
	}
	c->regs[HMC_STATUS] |= 0x01; /* RDY */
}

static void hmc_refresh(chip_t *c)
{
	board_t *b = c->board;
	double t = board_time_s(b);
	int mode = c->regs[HMC_MODE] & 3;
	if (mode == 0) { /* continuous */
		double rate = hmc_rates[(c->regs[HMC_CRA] >> 2) & 7];
		uint64_t k = (uint64_t)floor(t * rate);
		if (c->has_sample && k == c->last_sample)
			return;
		c->last_sample = k;
		c->has_sample = 1;
		hmc_store(c, k / rate);
	} else if (mode == 1) { /* single measurement: ready 6 ms after the request, then idle */
		if (t * 1e6 >= (double)c->data_read_sample) { /* data_read_sample holds the ready time, us */
			hmc_store(c, t);
			c->regs[HMC_MODE] = (uint8_t)((c->regs[HMC_MODE] & ~3) | 3);
		}
	}
}

static void hmc_write(chip_t *c, uint8_t reg, uint8_t v)
{
	if (reg > HMC_MODE)
		return;
	c->regs[reg] = v;
	if (reg == HMC_MODE) {
		c->has_sample = 0;
		if ((v & 3) == 1)
			c->data_read_sample = (uint64_t)(board_time_s(c->board) * 1e6) + 6000;
	}
}

static uint8_t hmc_read(chip_t *c, uint8_t reg)
{
	if (reg >= HMC_DATA && reg < HMC_STATUS)
		c->regs[HMC_STATUS] &= (uint8_t)~0x01;
	if (reg > 12)
		return 0;
	return c->latched[reg];
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

static void hmc_address(chip_t *c)
{
	hmc_refresh(c);
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
	if (b->real_timing) {
		uint8_t twbr = avr->data[0xB8], twps = avr->data[0xB9] & 3;
		avr_cycle_count_t scl = 16 + 2ULL * twbr * (1ULL << (2 * twps));
		avr_cycle_count_t want = b->msg_cycle + 9 * scl;
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
		if (b->real_timing)
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
			if (c->nack) {
				c->nacked++;
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
	if (b->cur_chip < 0)
		return;
	chip_t *c = &b->chip[b->cur_chip];
	if (c->nack) { /* went away in the middle of a transaction */
		b->i2c_errors++;
		b->cur_chip = -1;
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

void board_init(board_t *b, avr_t *avr, trace_t *trace, int verbose)
{
	memset(b, 0, sizeof(*b));
	b->avr = avr;
	b->trace = trace;
	b->verbose = verbose;
	b->log = stderr;
	b->cur_chip = -1;

	chip_t *a = &b->chip[CHIP_ADXL345];
	a->name = "adxl345";
	a->addr7 = 0x53;
	a->regs[ADXL_DEVID] = 0xE5;
	a->regs[ADXL_BW_RATE] = 0x0A;
	a->on_write = adxl_write;
	a->on_read = adxl_read;
	a->next_ptr = adxl_next;
	a->on_address = adxl_address;

	chip_t *g = &b->chip[CHIP_ITG3200];
	g->name = "itg3200";
	g->addr7 = 0x68;
	g->regs[ITG_WHO_AM_I] = 0x68;
	g->on_write = itg_write;
	g->on_read = itg_read;
	g->next_ptr = itg_next;
	g->on_address = itg_address;

	chip_t *m = &b->chip[CHIP_HMC5883L];
	m->name = "hmc5883l";
	m->addr7 = 0x1E;
	m->regs[HMC_CRA] = 0x10;
	m->regs[HMC_CRB] = 0x20;
	m->regs[HMC_MODE] = 0x01;
	m->regs[HMC_ID] = 'H';
	m->regs[HMC_ID + 1] = '4';
	m->regs[HMC_ID + 2] = '3';
	m->data_read_sample = 6000; /* single measurement at power-up */
	m->on_write = hmc_write;
	m->on_read = hmc_read;
	m->next_ptr = hmc_next;
	m->on_address = hmc_address;

	for (int i = 0; i < CHIP_COUNT; i++)
		b->chip[i].board = b;

	b->irq = avr_alloc_irq(&avr->irq_pool, 0, 2, irq_names);
	avr_irq_register_notify(b->irq + TWI_IRQ_OUTPUT, twi_hook, b);
	avr_connect_irq(b->irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
	avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), b->irq + TWI_IRQ_OUTPUT);

	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_STATUS), twi_status_hook, b);
	avr_register_io_write(avr, 0xBC, twcr_write_hook, b); /* TWCR */

	b->int1_pin = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
	b->int1_level = -1;
	adxl_update_int1(b);
	avr_cycle_timer_register(avr, avr->frequency / 1000, adxl_tick, b);
}
