/*
 * sensors.h - register-level models of the ADXL345, ITG-3200 and HMC5883L (or QMC5883L) on simavr's TWI
 * bus, each on its own oscillator, mounted on a board variant (README.md cites the datasheet sections).
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
/* The motion at t_s, linearly interpolated between the trace's samples (what a chip's ADC sees). */
void trace_interp(const trace_stream_t *s, double t_s, double out[3]);

/* The magnetometer slot holds an HMC5883L or a QMC5883L ("HMC5883L" modules often carry the latter). */
enum { CHIP_ADXL345 = 0, CHIP_ITG3200, CHIP_HMC5883L, CHIP_COUNT };
enum { MAG_HMC5883L = 0, MAG_QMC5883L };

/* A board variant: how each chip's axes sit in the body frame (the trace's frame). mount[chip][i] = +-(k+1):
 * the chip's axis i reads +- the body's axis k. */
typedef struct {
	const char *name;
	const char *description;
	int8_t mount[CHIP_COUNT][3];
	int mag_kind;
} board_variant_t;
extern const board_variant_t board_variants[];
const board_variant_t *board_variant_find(const char *name);

/* Imperfections of the chips beyond their logic (README: "Noise, offsets and clocks"). */
typedef struct {
	int noise;              /* datasheet noise, turn-on offsets, gyro warm-up drift with temperature */
	double ppm[CHIP_COUNT]; /* each chip's oscillator against the Nano's crystal, parts per million */
	uint64_t seed;
} imperfections_t;

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
	int holds_sda;          /* left mid-read by a reset: holds SDA low until clocked out (nine SCL pulses) */
	int glitch_nack;        /* fault: refuse the next address byte only */
};

/* ITG-3200 state: internal sampling, DLPF, warm-up (datasheet sections 3.1, 8.3). */
typedef struct {
	uint64_t internal_k;    /* index of the newest internal (1 or 8 kHz) sample computed */
	int running;
	double z1[3], z2[3];    /* DLPF biquad state (direct form II transposed), per axis */
	int dlpf_cfg;
	double bias0_dps[3], drift_dps_per_c[3];
	uint64_t rng;
	double on_s;            /* when it left reset/sleep: start-up and warm-up run from here */
	double out[3];          /* newest filtered output, deg/s */
} itg_state_t;

/* HMC5883L state (datasheet "Modes of operation", status and data output registers). */
typedef struct {
	double next_done_s;     /* chip time when the measurement under way completes; < 0 none */
	double rdy_clear_until_s;
	uint8_t read_mask;      /* data output bytes read since the last unlock (bit i: register 3 + i) */
	int locked;
	int pending;            /* a completed measurement waiting for the lock to open */
	int16_t pending_out[3];
	double pending_ct;
	uint64_t rng;
	uint32_t measurements, dropped_locked;
} hmc_state_t;

/* QMC5883L state (QST datasheet section 9). */
typedef struct {
	uint64_t k;             /* index of the newest sample */
	int has;
	double on_s;
	uint64_t rng;
} qmc_state_t;

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
	avr_irq_t *sda_pin;      /* PC4: driven low while a chip holds SDA */
	avr_irq_t *drdy_pin;     /* the ATmega pin HMC5883L DRDY drives (--drdy-pin), NULL when not wired */
	int drdy_low;
	int sda_pin_low;
	int int1_level;
	uint8_t adxl_int_source;
	uint8_t adxl_act_tap_status;
	uint64_t adxl_tick;      /* ODR index of the engine's newest sample */
	double adxl_odr_hz;
	int adxl_timer_running;
	/* ADXL345 FIFO ("FIFO", "Register 0x38—FIFO_CTL", "Register 0x39—FIFO_STATUS"): 32 sample sets, oldest
	 * first; in FIFO, stream and trigger mode the data registers hold the oldest, and reading them takes it out */
	int16_t adxl_fifo[32][3];
	double adxl_fifo_t[32];  /* when each was sampled (simulated s) */
	int adxl_fifo_n;
	int adxl_fifo_trig;      /* trigger mode: the trigger event came (FIFO_STATUS bit 7) */
	int adxl_popped;         /* the current transaction has taken a set out */
	double adxl_data_t;      /* when the set in the data registers (bypass mode) was sampled */
	/* the age of the data the AVR read: the largest, and the first read after each program start */
	double adxl_age_max_ms;
	double adxl_first_age_ms[64];
	int adxl_first_ages, adxl_age_pending;
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
	/* variant and imperfections */
	const board_variant_t *variant;
	imperfections_t imp;
	itg_state_t itg;
	hmc_state_t hmc;
	qmc_state_t qmc;
	uint64_t adxl_rng;
	double adxl_offset_lsb[3]; /* zero-g offset (noise mode), full-resolution LSB */
	double power_on_s;         /* the chips' last power-on (start or brown-out) */
	uint32_t sda_held_events, glitch_nacks, clock_stretches;
	avr_cycle_count_t stretch_cycles; /* fault: the addressed slave stretches the next byte by this much */
	int reset_on_read;       /* fault: reset the AVR right after the next byte a slave sends */
	int reset_pending;       /* ... that byte was sent: the main loop resets the AVR now */
	void (*on_fault)(struct board_t *b, const char *kind, int chip); /* a fault took effect (log) */
} board_t;

void board_init(board_t *b, avr_t *avr, trace_t *trace, int verbose, const board_variant_t *variant,
                const imperfections_t *imp);
/* The chips lose power (a brown-out) and come back at power-on state at the current time. */
void board_power_cycle(board_t *b);
/* Reset the chips' bus state after a reset of the AVR; a chip in the middle of a read keeps SDA low. */
void board_avr_reset(board_t *b);
/* The SCL line as the AVR drives it while the TWI is off (PC5: DDR and PORT): nine clocks release SDA. */
void board_scl_level(board_t *b, int level);
int board_sda_held(board_t *b);
void board_sda_update(board_t *b);
/* An AVR reset cancels every cycle timer (simavr): start the chips' own again. */
void board_restart_timers(board_t *b);
/* Wire the HMC5883L's DRDY to an ATmega pin. */
void board_wire_drdy(board_t *b, avr_irq_t *pin);
/* The chip's own time for board time t_s (its oscillator's ppm offset). */
double chip_time(board_t *b, int chip, double t_s);
double board_time_s(board_t *b);

#endif
