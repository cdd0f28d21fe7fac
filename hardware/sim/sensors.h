/*
 * sensors.h - register-level models of the ADXL345, ITG-3200 and HMC5883L on simavr's TWI bus.
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
 */
#ifndef SPHERE_SENSORS_H
#define SPHERE_SENSORS_H

#include <stdint.h>
#include <stdio.h>
#include "sim_avr.h"
#include "sim_irq.h"

/* One stream of a motion trace: samples in the chip's units at the nominal configuration
 * (ADXL345 full resolution 256 LSB/g, ITG-3200 14.375 LSB/(deg/s), HMC5883L gain 1: 1090 LSB/gauss,
 * already saturated as the chip would), x, y, z, at rate_hz, starting at simulated time 0. */
typedef struct {
	double rate_hz;
	uint32_t count;
	int16_t *xyz; /* count * 3 */
} trace_stream_t;

typedef struct {
	trace_stream_t accel, gyro, mag;
} trace_t;

int trace_load(trace_t *t, const char *path, char *err, size_t errlen);
/* The sample in effect at simulated time t_s (zero-order hold; the last sample after the end). */
const int16_t *trace_at(const trace_stream_t *s, double t_s);

enum { CHIP_ADXL345 = 0, CHIP_ITG3200, CHIP_HMC5883L, CHIP_COUNT };

typedef struct chip_t chip_t;
struct chip_t {
	const char *name;
	uint8_t addr7;          /* 7-bit I2C address */
	uint8_t regs[64];
	uint8_t latched[64];    /* data registers as latched at the start of a transaction */
	uint8_t ptr;            /* register pointer */
	int selected;           /* addressed in the current transaction: 1 write, 2 read */
	int index;              /* bytes written in the current write transaction */
	int nack;               /* fault: does not acknowledge its address */
	uint64_t last_sample;   /* ODR index of the newest sample made */
	int has_sample;
	uint64_t data_read_sample; /* ODR index of the sample last read out */
	/* counters */
	uint32_t addressed, nacked;
	/* behaviour */
	void (*on_address)(chip_t *c);                 /* a transaction addressed this chip */
	void (*on_write)(chip_t *c, uint8_t reg, uint8_t v);
	uint8_t (*on_read)(chip_t *c, uint8_t reg);
	uint8_t (*next_ptr)(chip_t *c, uint8_t reg);
	struct board_t *board;
};

/* ADXL345 tap / free-fall engine state (datasheet rev. E, "Tap detection", "Free-fall"). */
typedef struct {
	int above;               /* an enabled axis is above THRESH_TAP */
	uint64_t above_start_us;
	uint8_t above_axes;      /* axes above at the rising edge: bit 2 x, 1 y, 0 z */
	int second;              /* 0 waiting for a first tap, 1 latency, 2 window */
	uint64_t first_tap_end_us;
	int suppressed;
	uint64_t ff_start_us;
	int ff_below;
} tap_engine_t;

typedef struct board_t {
	avr_t *avr;
	trace_t *trace;
	chip_t chip[CHIP_COUNT];
	tap_engine_t tap;
	avr_irq_t *irq;          /* our TWI irqs: [0] input (to the AVR), [1] output (from the AVR) */
	avr_irq_t *int1_pin;     /* ATmega pin that ADXL345 INT1 drives (D2 = PD2) */
	int int1_level;
	uint8_t adxl_int_source;
	uint8_t adxl_act_tap_status;
	uint64_t adxl_tick;      /* ODR index of the engine's newest sample */
	double adxl_odr_hz;
	int adxl_timer_running;
	/* bus bookkeeping */
	int bus_busy;            /* between a START and a STOP */
	int cur_chip;            /* chip addressed now, -1 none */
	uint32_t transactions, i2c_errors, starts, addr_nacks;
	int start_armed;         /* the next START opens a sample period's work (loop timing fallback) */
	avr_cycle_count_t first_start_cycle;
	int stalled;             /* fault: the bus is stalled */
	void *twi;               /* simavr's TWI module (the parameter of its step timer) */
	int real_timing;         /* stretch each TWI byte step to 9 SCL periods at the TWBR rate */
	avr_cycle_count_t msg_cycle;
	int fix_status;          /* report 0x18/0x20 after SLA+W, as the real TWI does (simavr 1.6: 0x28/0x30) */
	int sla_w_pending;
	uint32_t stalled_ops;
	uint32_t events_single_tap, events_double_tap, events_free_fall;
	int verbose;
	FILE *log;
} board_t;

void board_init(board_t *b, avr_t *avr, trace_t *trace, int verbose);
double board_time_s(board_t *b);

#endif
