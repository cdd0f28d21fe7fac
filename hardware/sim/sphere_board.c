/*
 * sphere_board.c - the MARG sphere's virtual board: the real firmware image on a simulated
 * ATmega328P at 16 MHz (simavr), with register-level ADXL345, ITG-3200 and HMC5883L models on its
 * I2C bus fed by a recorded motion trace, its UART into a capture file and/or a pseudo-terminal,
 * fault injection, and cycle-exact timing of the MARG update from the timing pin.
 *
 * Part of the MARG sphere project (hardware/sim).
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
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <limits.h>
#ifdef __linux__
#include <sys/prctl.h>
#include <termios.h>
#include <fcntl.h>
#endif

#include "sim_avr.h"
#include "sim_elf.h"
#include "sim_io.h"
#include "sim_cycle_timers.h"
#include "sim_interrupts.h"
#include <stdint.h>
#include "avr_ioport.h"
#include "avr_uart.h"
#include "avr_extint.h"
#include "parts/uart_pty.h"
#include "sensors.h"
#include "mcu.h"

/* per kind of scheduled fault: a soak puts one fault every 4-7 s, so an hour holds ~130 of each kind */
#define MAX_FAULTS 1024

typedef struct {
	int chip;     /* CHIP_* for a NACK, -1 for a bus stall */
	double start_s, end_s;
	int active;
} fault_t;

typedef struct {
	uint32_t *v;
	size_t n, cap;
} vec_t;

static void vec_push(vec_t *v, uint32_t x)
{
	if (v->n == v->cap) {
		v->cap = v->cap ? 2 * v->cap : 1024;
		v->v = realloc(v->v, v->cap * sizeof(uint32_t));
	}
	v->v[v->n++] = x;
}

static int cmp_u32(const void *a, const void *b)
{
	uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
	return x < y ? -1 : x > y;
}

typedef struct {
	board_t *board;
	avr_cycle_count_t rise, last_rise;
	int high, have_last_rise;
	vec_t update, loop;
	uint32_t long_pulses, overruns, updates;
	avr_cycle_count_t period_cycles;
	int is_loop_pin;
} timing_t;

static timing_t tm_update, tm_loop;
static int have_loop_pin;

/* The sample clock's interrupt: the vector that runs at the sample rate (found after 0.5 s). */
#define N_VECTORS 26
static uint32_t vec_count[N_VECTORS];
static avr_cycle_count_t vec_last[N_VECTORS];
static int tick_vector = -1, tick_searched;
static FILE *g_host_log; /* --host-log (below): also each entry of the sample clock's interrupt, "S simulated_s ns" */
static vec_t loop_tick; /* tick ISR entry .. end of the MARG update */

static void vector_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	if (!value)
		return;
	int v = (int)(intptr_t)param;
	vec_count[v]++;
	vec_last[v] = tm_update.board->avr->cycle;
	if (v == tick_vector && g_host_log) { /* when a sample period starts: the time its sample's t_us stands for */
		struct timespec now;
		clock_gettime(CLOCK_MONOTONIC, &now);
		avr_t *avr = tm_update.board->avr;
		fprintf(g_host_log, "S %.9f %lld\n", (double)avr->cycle / avr->frequency,
			(long long)now.tv_sec * 1000000000LL + now.tv_nsec);
	}
}

/* Called at update ends: snapshot the vectors' counts once 0.5 s have passed, decide 0.5 s later. */
static uint32_t vec_snap[N_VECTORS];
static avr_cycle_count_t snap_cycle;
static void find_tick_vector(avr_t *avr)
{
	if (!snap_cycle) {
		snap_cycle = avr->cycle;
		memcpy(vec_snap, vec_count, sizeof vec_snap);
		return;
	}
	if (avr->cycle - snap_cycle < avr->frequency / 2)
		return;
	double t = (double)(avr->cycle - snap_cycle) / avr->frequency, rate = (double)avr->frequency / tm_update.period_cycles;
	tick_searched = 1;
	for (int v = 1; v < N_VECTORS; v++)
		if (fabs((vec_count[v] - vec_snap[v]) / t - rate) < 0.03 * rate) {
			tick_vector = v;
			return;
		}
}

static void pin_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	timing_t *t = param;
	avr_t *avr = t->board->avr;
	if (value && !t->high) {
		t->high = 1;
		t->rise = avr->cycle;
	} else if (!value && t->high) {
		t->high = 0;
		avr_cycle_count_t d = avr->cycle - t->rise;
		if (d > t->period_cycles) { /* longer than a sample period: the LED, not the update */
			t->long_pulses++;
			return;
		}
		vec_push(&t->update, (uint32_t)d);
		t->updates++;
		/* a sample period with no update: consecutive update starts more than 1.5 periods apart
		 * (gaps longer than 100 periods are start-up or a stopped stream, not overruns) */
		if (!t->is_loop_pin) {
			avr_cycle_count_t gap = t->rise - t->last_rise;
			if (t->have_last_rise && gap > t->period_cycles * 3 / 2 && gap < t->period_cycles * 100)
				t->overruns += (uint32_t)((gap + t->period_cycles / 2) / t->period_cycles) - 1;
			t->last_rise = t->rise;
			t->have_last_rise = 1;
		}
		if (!t->is_loop_pin) {
			if (!tick_searched && avr->cycle > avr->frequency / 2)
				find_tick_vector(avr);
			if (tick_vector > 0 && avr->cycle - vec_last[tick_vector] < t->period_cycles)
				vec_push(&loop_tick, (uint32_t)(avr->cycle - vec_last[tick_vector]));
		}
		if (!t->is_loop_pin && !have_loop_pin) {
			board_t *b = t->board;
			if (!b->start_armed && avr->cycle > b->first_start_cycle &&
			    avr->cycle - b->first_start_cycle <= 4 * t->period_cycles)
				vec_push(&tm_loop.update, (uint32_t)(avr->cycle - b->first_start_cycle));
			b->start_armed = 1;
		}
	}
}

/* ---------------------------------------------------------------- UART */

typedef struct {
	FILE *capture;
	uint64_t bytes;
	uint32_t frames;
	int last_nonzero;
	/* the host side: a USB-serial adapter whose buffer overflows while the host does not read */
	avr_t *avr;
	int host_reading;
	uint32_t adapter_buffer, buffered;
	uint64_t host_dropped, captured;
	FILE *times; /* --capture-times: (u64 capture offset, f64 simulated s) at every frame delimiter */
	/* --adapter: USB packets and latency (0 packet: bytes reach the host as they leave the UART) */
	uint32_t packet, pending;
	uint8_t pend[64];
	avr_cycle_count_t latency_cycles, last_packet;
	/* FTDI: the latency timer the driver sets (--latency-timer, 16 ms by default) and the one it sets when the
	 * host asks for low latency (1 ms), read from the pty's termios (pty_fd: the master; "The host's requests") */
	int ftdi, pty_fd, host_low_latency;
	uint32_t latency_ms;
	/* what reaches the pty in one write (a USB packet, or one byte without an adapter), paced to the wall clock */
	uint8_t out[512];
	uint32_t n_out, out_delims;
	uint64_t pty_dropped;
	int realtime;
	double frame_start_s;
	FILE *host_log; /* --host-log: frames leaving the UART and reaching the pty, for `sphere bench latency` */
	/* the two ends' baud rates (pty only): the AVR's from UBRR0/U2X0, the host's from the pty's termios */
	double host_baud;
	uint64_t garbled_out, garbled_in;
	struct termios untouched; /* the pty's termios as made: until a host changes it, no host has set a rate */
	int host_configured;
} uart_out_t;

static double board_wall0; /* CLOCK_MONOTONIC s at simulated time 0 (--realtime pacing) */
static double wall_now(void);

static uart_out_t uart_out;

/* ---------------------------------------------------------------- fault log (for --stats) */

typedef struct {
	double t_s;
	const char *kind;
	int chip;
} fault_event_t;
static fault_event_t *fault_log;
static size_t n_fault_log, cap_fault_log;

static void log_fault(double t_s, const char *kind, int chip)
{
	if (n_fault_log == cap_fault_log) {
		cap_fault_log = cap_fault_log ? 2 * cap_fault_log : 64;
		fault_log = realloc(fault_log, cap_fault_log * sizeof *fault_log);
	}
	fault_log[n_fault_log++] = (fault_event_t){t_s, kind, chip};
}

static void board_fault(board_t *b, const char *kind, int chip) { log_fault(board_time_s(b), kind, chip); }

/* A byte reaches the host: into the capture (and its time), and the pty when there is one. */
static void host_receives(uart_out_t *u, uint8_t byte)
{
	if (u->capture)
		fputc(byte, u->capture);
	u->captured++;
	if (u->times && byte == 0) {
		uint64_t off = u->captured;
		double t = (double)u->avr->cycle / u->avr->frequency;
		fwrite(&off, 8, 1, u->times);
		fwrite(&t, 8, 1, u->times);
	}
	if (u->pty_fd > 0 && u->n_out < sizeof u->out) {
		u->out[u->n_out++] = byte;
		u->out_delims += byte == 0;
	}
}

/* What the host received since the last call reaches the pty now: with --realtime not before its simulated time
 * on the wall clock (the main loop alone lets the simulation run up to 2 ms ahead), and written by this thread
 * (simavr's pty thread would add up to its 0.5 ms select period). --host-log: "P simulated_s monotonic_ns frames". */
static void host_deliver(uart_out_t *u)
{
	if (!u->n_out)
		return;
	double sim_s = (double)u->avr->cycle / u->avr->frequency;
	if (u->realtime) {
		double ahead = board_wall0 + sim_s - wall_now();
		if (ahead > 50e-6) {
			struct timespec ts = {(time_t)ahead, (long)((ahead - floor(ahead)) * 1e9)};
			nanosleep(&ts, NULL);
		}
	}
	/* the time is read before the write: a host woken by it (sphere-mouse's loop runs in real time) may run its
	 * whole frame before this thread gets the core back, and a time read after would leave that out */
	struct timespec now;
	clock_gettime(CLOCK_MONOTONIC, &now);
	ssize_t w = write(u->pty_fd, u->out, u->n_out); /* non-blocking: nobody reading drops, as a full adapter does */
	if (w < (ssize_t)u->n_out)
		u->pty_dropped += u->n_out - (w > 0 ? (uint32_t)w : 0);
	if (u->host_log && u->out_delims)
		fprintf(u->host_log, "P %.9f %lld %u\n", sim_s, (long long)now.tv_sec * 1000000000LL + now.tv_nsec, u->out_delims);
	u->n_out = u->out_delims = 0;
}

/* The adapter sends what it holds as one USB packet. */
static void adapter_flush(uart_out_t *u)
{
	for (uint32_t i = 0; i < u->pending; i++)
		host_receives(u, u->pend[i]);
	host_deliver(u);
	u->pending = 0;
	u->last_packet = u->avr->cycle;
}

/* The host's low-latency request (ASYNC_LOW_LATENCY) reaches a pty as termios CMSPAR without PARENB (the kernel
 * keeps CMSPAR on a pty and clears PARENB; tcgetattr on the master reads the slave's termios): ftdi_sio then
 * writes 1 ms into the FT232R's latency timer, so the model does the same. A host that opens the port again
 * without asking gets the default back, as pyserial's open rewrites the termios without CMSPAR. */
#ifndef CMSPAR
#define CMSPAR 010000000000
#endif
static void host_latency_request(uart_out_t *u)
{
	struct termios tio;
	if (tcgetattr(u->pty_fd, &tio) != 0)
		return;
	int low = (tio.c_cflag & CMSPAR) && !(tio.c_cflag & PARENB);
	if (low == u->host_low_latency)
		return;
	u->host_low_latency = low;
	u->latency_cycles = (avr_cycle_count_t)(low ? 1 : u->latency_ms) * (u->avr->frequency / 1000);
	log_fault((double)u->avr->cycle / u->avr->frequency, low ? "host_low_latency" : "host_default_latency", -1);
}

/* FTDI FT232R (AN232B-04): a packet when 62 data bytes are waiting, or when the latency timer (16 ms) runs
 * out with data waiting. CH340: no latency timer in its datasheet; the model sends a 32-byte packet when
 * full, or what is waiting at each 1 ms USB frame. */
static avr_cycle_count_t adapter_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
	uart_out_t *u = param;
	if (u->ftdi && u->pty_fd > 0)
		host_latency_request(u);
	if (u->pending && when - u->last_packet >= u->latency_cycles)
		adapter_flush(u);
	return when + avr->frequency / 1000;
}

/* The baud rate the AVR's UART runs at (ATmega328P datasheet, "USART0", Table 20-1: UBRR0 and U2X0). */
static double avr_uart_baud(avr_t *avr)
{
	unsigned ubrr = avr->data[0xC4] | ((avr->data[0xC5] & 0x0F) << 8); /* UBRR0L, UBRR0H */
	int u2x = avr->data[0xC0] & 0x02;                                  /* UCSR0A: U2X0 */
	return (double)avr->frequency / ((u2x ? 8.0 : 16.0) * (ubrr + 1));
}

static double speed_baud(speed_t s)
{
	static const struct { speed_t s; double baud; } table[] = {
		{B9600, 9600}, {B19200, 19200}, {B38400, 38400}, {B57600, 57600}, {B115200, 115200}, {B230400, 230400},
		{B460800, 460800}, {B500000, 500000}, {B576000, 576000}, {B921600, 921600}, {B1000000, 1000000},
		{B1152000, 1152000}, {B1500000, 1500000}, {B2000000, 2000000},
	};
	for (size_t i = 0; i < sizeof table / sizeof table[0]; i++)
		if (table[i].s == s)
			return table[i].baud;
	return 0;
}

/* The host's rate as the pty's termios says: the adapter's UART runs at what the host set, from the moment it set
 * it (a real driver's baud change is a USB control transfer done before its next write), so it is read at every
 * byte that crosses. */
static void host_baud_poll(uart_out_t *u)
{
	struct termios tio;
	if (u->pty_fd > 0 && tcgetattr(u->pty_fd, &tio) == 0) {
		/* a pty starts at the kernel's 38400 (never the sphere's rate): a host that opens the port sets its own */
		if (!u->host_configured && cfgetospeed(&tio) != cfgetospeed(&u->untouched))
			u->host_configured = 1;
		u->host_baud = speed_baud(cfgetospeed(&tio));
	}
}

/* A byte crosses the serial line intact only when both ends run at the same rate: a UART tolerates about
 * ±2 % between them (ATmega328P datasheet, "Asynchronous Operational Range", Table 20-2/20-3: 8 data bits,
 * ±2.0 to ±3.0 %). Otherwise the receiver samples the wrong bits: a garbled byte (and a frame that fails). */
static int rates_match(uart_out_t *u, double avr)
{
	host_baud_poll(u);
	if (u->pty_fd <= 0 || u->host_baud <= 0 || !u->host_configured)
		return 1; /* nobody has set a rate yet: nothing to disagree with */
	return fabs(avr - u->host_baud) <= 0.03 * u->host_baud;
}

static uint8_t garble(uint8_t byte) { return (uint8_t)(byte * 37u + 11u); }

static avr_irq_t *uart_in_irq;

/* Host -> AVR: what simavr's pty thread hands over, garbled when the rates differ. */
static void pty_to_avr_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	uart_out_t *u = param;
	uint8_t byte = (uint8_t)value;
	if (!rates_match(u, avr_uart_baud(u->avr))) {
		byte = garble(byte);
		u->garbled_in++;
	}
	avr_raise_irq(uart_in_irq, byte);
}

/* A byte the firmware wrote into UDR0 reaches the host's UART when its frame has been shifted out: the receiver
 * moves a byte into its buffer once it has the stop bit ("Receiving Frames with 5 to 8 Data Bits", ATmega328P
 * datasheet "USART0"), and the sender's TXC0 rises "when the entire frame in the Transmit Shift Register has been
 * shifted out" ("Transmitter Flags and Interrupts"), which simavr raises one frame time after the UDR0 write (it
 * models no second transmit buffer: UDRE0 rises then too). So a byte goes to the host one frame time (10 bits, 8N1,
 * at the rate UBRR0 set when it was written) after the write, not at it: never before the sphere's TXC0, which a
 * host reacting to the byte (SET_BAUD's REPLY, spec §5.4) cannot beat on a real line either. */
#define TX_FLIGHT 64
static struct { uint8_t byte; double baud; avr_cycle_count_t written, due; } tx_flight[TX_FLIGHT];
static unsigned tx_head, tx_n;

static void uart_byte_arrives(uart_out_t *u, uint8_t byte, double avr_baud, avr_cycle_count_t written);

static avr_cycle_count_t tx_flight_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
	while (tx_n && tx_flight[tx_head].due <= when) {
		unsigned i = tx_head;
		tx_head = (tx_head + 1) % TX_FLIGHT;
		tx_n--;
		uart_byte_arrives(param, tx_flight[i].byte, tx_flight[i].baud, tx_flight[i].written);
	}
	return tx_n ? tx_flight[tx_head].due : 0;
}

static void uart_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	uart_out_t *u = param;
	avr_t *avr = u->avr;
	double baud = avr_uart_baud(avr);
	if (tx_n && !avr_cycle_timer_status(avr, tx_flight_timer, u)) /* a reset cancelled the timer: what was on */
		tx_flight_timer(avr, (avr_cycle_count_t)-1, u);           /* the line when it came is out */
	if (tx_n == TX_FLIGHT) { /* a firmware writing UDR0 faster than its frames leave: no room to model it */
		uart_byte_arrives(u, (uint8_t)value, baud, avr->cycle);
		return;
	}
	avr_cycle_count_t frame = (avr_cycle_count_t)(avr->frequency * 10.0 / baud + 0.5);
	/* frames leave one after another: a byte written while the one before is still on the line follows it */
	avr_cycle_count_t start = tx_n ? tx_flight[(tx_head + tx_n - 1) % TX_FLIGHT].due : avr->cycle;
	if (start < avr->cycle)
		start = avr->cycle;
	unsigned i = (tx_head + tx_n) % TX_FLIGHT;
	tx_flight[i].byte = (uint8_t)value;
	tx_flight[i].baud = baud;
	tx_flight[i].written = avr->cycle;
	tx_flight[i].due = start + frame;
	if (!tx_n++)
		avr_cycle_timer_register(avr, tx_flight[i].due - avr->cycle, tx_flight_timer, u);
}

/* The byte has crossed the line: garbled when the host's UART runs at another rate than the one it was sent at. */
static void uart_byte_arrives(uart_out_t *u, uint8_t byte, double avr_baud, avr_cycle_count_t written)
{
	if (!rates_match(u, avr_baud)) { /* the adapter's UART samples at the host's rate */
		byte = garble(byte);
		u->garbled_out++;
	}
	u->bytes++;
	if (byte == 0) {
		if (u->last_nonzero) {
			u->frames++;
			if (u->host_log) /* "U first_byte_s delimiter_s": the first byte written into UDR0 (its start bit
			                  * begins), the delimiter's stop bit over (now) */
				fprintf(u->host_log, "U %.9f %.9f\n", u->frame_start_s, (double)u->avr->cycle / u->avr->frequency);
		}
		u->last_nonzero = 0;
	} else {
		if (!u->last_nonzero)
			u->frame_start_s = (double)written / u->avr->frequency;
		u->last_nonzero = 1;
	}
	if (!u->host_reading) { /* the adapter keeps what fits in its buffer and drops the rest */
		if (u->buffered >= u->adapter_buffer) {
			u->host_dropped++;
			return;
		}
		u->buffered++;
	}
	if (!u->packet) {
		host_receives(u, byte);
		host_deliver(u);
		return;
	}
	u->pend[u->pending++] = byte;
	if (u->pending >= u->packet)
		adapter_flush(u);
}

/* Bytes for the device's UART from a file of lines "SECONDS HEX HEX ...". */
typedef struct {
	double t_s;
	uint8_t *bytes;
	size_t n;
} uart_send_t;

static uart_send_t *sends;
static size_t n_sends, send_i, send_pos;
static int uart_xon = 1;

static void xon_hook(struct avr_irq_t *irq, uint32_t v, void *p) { (void)irq; (void)v; (void)p; uart_xon = 1; }
static void xoff_hook(struct avr_irq_t *irq, uint32_t v, void *p) { (void)irq; (void)v; (void)p; uart_xon = 0; }

static avr_cycle_count_t uart_send_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
	(void)param;
	if (send_i >= n_sends)
		return 0;
	uart_send_t *s = &sends[send_i];
	if ((double)when / avr->frequency < s->t_s)
		return when + avr->frequency / 10000;
	if (uart_xon) {
		avr_raise_irq(uart_in_irq, s->bytes[send_pos++]);
		if (send_pos >= s->n) {
			send_pos = 0;
			send_i++;
		}
	}
	return when + avr->frequency / 11520; /* one byte time at 115200 baud 8N1 */
}

static int load_sends(const char *path)
{
	FILE *f = fopen(path, "r");
	if (!f) {
		fprintf(stderr, "sphere-board: cannot open %s\n", path);
		return -1;
	}
	char line[4096];
	while (fgets(line, sizeof line, f)) {
		char *p = line, *end;
		while (*p == ' ' || *p == '\t') p++;
		if (*p == '#' || *p == '\n' || !*p)
			continue;
		double t = strtod(p, &end);
		if (end == p)
			continue;
		sends = realloc(sends, (n_sends + 1) * sizeof(*sends));
		uart_send_t *s = &sends[n_sends++];
		s->t_s = t;
		s->bytes = malloc(strlen(line));
		s->n = 0;
		p = end;
		for (;;) {
			long v = strtol(p, &end, 16);
			if (end == p)
				break;
			s->bytes[s->n++] = (uint8_t)v;
			p = end;
		}
	}
	fclose(f);
	return 0;
}

/* ---------------------------------------------------------------- faults */

static int chip_by_name(const char *name)
{
	if (!strcmp(name, "adxl345") || !strcmp(name, "accel")) return CHIP_ADXL345;
	if (!strcmp(name, "itg3200") || !strcmp(name, "gyro")) return CHIP_ITG3200;
	if (!strcmp(name, "hmc5883l") || !strcmp(name, "qmc5883l") || !strcmp(name, "mag")) return CHIP_HMC5883L;
	return -1;
}

static avr_io_t *find_io(avr_t *avr, const char *kind)
{
	for (avr_io_t *io = avr->io_port; io; io = io->next)
		if (io->kind && !strcmp(io->kind, kind))
			return io;
	return NULL;
}

/* A stalled bus: a slave holds the clock, so the TWI never finishes its step and TWINT never rises.
 * simavr finishes each TWI step from a cycle timer whose parameter is the TWI module: cancel it. */
static uint32_t stalled_steps;
static void hold_twi(avr_t *avr, void *twi)
{
	avr_cycle_timer_t fn[8];
	int n = 0;
	for (avr_cycle_timer_slot_p s = avr->cycle_timers.timer; s && n < 8; s = s->next)
		if (s->param == twi)
			fn[n++] = s->timer;
	for (int i = 0; i < n; i++)
		avr_cycle_timer_cancel(avr, fn[i], twi);
	stalled_steps += (uint32_t)n; /* each a bus step that never completes */
}

/* ---------------------------------------------------------------- main */

static volatile sig_atomic_t stop_requested;
static void on_signal(int sig) { (void)sig; stop_requested = 1; }

static double cpu_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static double wall_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static uint32_t resets;
static board_t *the_board;
static int plain_reset; /* --reset-at: a reset that leaves no chip holding SDA (the soak's reference run) */

/* MCUSR and SRAM over the resets (ATmega328P datasheet, "System Control and Reset": "Reset Sources", "MCU
 * Status Register - MCUSR"). A power-on reset sets PORF, and EXTRF, BORF and WDRF are "reset by a Power-on
 * Reset"; an external, brown-out or watchdog reset sets its own flag and leaves the others as they were
 * until the program writes 0 to them. "During reset, all I/O Registers are set to their initial values":
 * SRAM is not an I/O register and no reset source writes it, so it keeps its contents over every reset but
 * a power-on, after which its contents are not defined (the model: seeded random bytes).
 * simavr 1.6's avr_reset (measured with hardware/sim/probe, tests/e2e/test_board_chips.py) keeps SRAM but
 * clears every I/O register, MCUSR too, and sets no flag for an external reset; its watchdog sets WDRF
 * after its reset. The board puts back the flags MCUSR held before (read after every instruction step) and
 * adds the flag of its own reset. */
enum { MCUSR_PORF = 1, MCUSR_EXTRF = 2, MCUSR_BORF = 4, MCUSR_WDRF = 8 };
static uint16_t mcusr_addr = 0x54;  /* MCUSR in the ATmega328P's data space (I/O 0x34) */
static uint8_t mcusr_before;        /* MCUSR as the program left it */
static uint8_t reset_flag;          /* the flag of the reset the board makes now (0: simavr's watchdog) */

/* SRAM after a power-on: not defined by the datasheet; seeded random bytes, so a program that trusts it shows */
static void sram_power_on(avr_t *avr, uint64_t seed, uint32_t power_ons)
{
	uint64_t r = (seed + 1) * 0x9E3779B97F4A7C15ULL ^ (0xA5A5A5A5ULL + power_ons);
	for (uint32_t a = 0x100; a <= avr->ramend; a++) {
		r ^= r >> 12; r ^= r << 25; r ^= r >> 27;
		avr->data[a] = (uint8_t)((r * 0x2545F4914F6CDD1DULL) >> 56);
	}
}

/* the board's own resets: kind MCUSR_EXTRF (reset pin), MCUSR_BORF (brown-out detector) or MCUSR_PORF
 * (the supply went below the power-on threshold: SRAM lost, the other flags cleared) */
static void reset_avr(avr_t *avr, uint8_t kind, uint64_t seed)
{
	static uint32_t power_ons;
	reset_flag = kind;
	if (kind == MCUSR_PORF) {
		mcusr_before = 0;
		mcu_watchdog_forget_pending(avr);
	}
	avr_reset(avr);
	reset_flag = 0;
	if (kind == MCUSR_PORF)
		sram_power_on(avr, seed, ++power_ons);
	mcusr_before = avr->data[mcusr_addr];
	mcu_watchdog_after_reset(avr, mcusr_before); /* WDRF still set keeps the watchdog on (mcu.c) */
}

/* INT0/INT1 in low-level mode (ISC = 00, the reset value): simavr 1.6 (avr_extint.c) then polls the pin every
 * cycle while it is low and keeps polling after the program picks an edge mode (the poll reads the pin, never
 * ISC), raising INT0 whenever it is low: a cycle timer due at every cycle, most of the board's time
 * (avr_ioctl at the top of a profile) and no idle cycles to skip while the AVR sleeps. The datasheet's level
 * interrupt ("triggered as long as the pin is held low", External Interrupts, EICRA) applies only while
 * ISC = 00, which neither the firmware (rising edge, avr_board.cpp) nor the boot loaders use; simavr's
 * non-strict mode raises it once per low level instead. simavr sets the strict mode again at every reset
 * (after the board's own reset hook), so the board turns it off after each. */
static void extint_level_poll_off(avr_t *avr)
{
	avr_extint_set_strict_lvl_trig(avr, 0, 0);
	avr_extint_set_strict_lvl_trig(avr, 1, 0);
}

/* the watchdog's system reset where simavr 1.6 makes none (mcu.c, (2)): as simavr's own, WDRF and WDE set */
static void watchdog_reset_avr(avr_t *avr)
{
	mcu_watchdog_reset(avr);
	avr_reset(avr);
	mcusr_before = avr->data[mcusr_addr];
}

static void on_reset(avr_t *avr)
{
	resets++;
	/* a reset starts the program at the reset vector, asleep or not (ATmega328P datasheet, System Control and
	 * Reset: "all I/O Registers are set to their initial values, and the program starts execution from the
	 * Reset Vector"); simavr 1.6's avr_reset leaves avr->state alone, so a brown-out that came while the
	 * firmware slept in its loop left it asleep with interrupts off until the watchdog */
	if (avr->state == cpu_Sleeping)
		avr->state = cpu_Running;
	avr->data[mcusr_addr] = (uint8_t)(mcusr_before | reset_flag);
	mcu_on_reset();
	avr->pc = avr->reset_pc; /* the boot loader's first address with --bootloader (BOOTRST), else 0 */
	tm_update.have_last_rise = 0; /* the program starts again: the gap before its first update is no overrun */
	tm_update.high = tm_loop.high = 0; /* a pulse the reset cuts (the pin falls as PORTB clears) is no update */
	if (the_board && !plain_reset)
		board_avr_reset(the_board); /* the chips keep their power: one in the middle of a read holds SDA */
	else if (the_board) {
		int held[CHIP_COUNT];
		for (int i = 0; i < CHIP_COUNT; i++)
			held[i] = the_board->chip[i].holds_sda;
		board_avr_reset(the_board);
		for (int i = 0; i < CHIP_COUNT; i++)
			the_board->chip[i].holds_sda = held[i];
	}
}

static void no_sleep(avr_t *avr, avr_cycle_count_t howLong) { (void)avr; (void)howLong; }

static void stats3(FILE *f, const char *name, vec_t *v)
{
	if (!v->n) {
		fprintf(f, "  \"%s\": {\"min\": null, \"median\": null, \"max\": null, \"count\": 0},\n", name);
		return;
	}
	qsort(v->v, v->n, sizeof(uint32_t), cmp_u32);
	fprintf(f, "  \"%s\": {\"min\": %u, \"median\": %u, \"max\": %u, \"count\": %zu},\n", name, v->v[0],
		v->v[v->n / 2], v->v[v->n - 1], v->n);
}

static int parse_pin(const char *s, char *port, int *bit)
{
	if (strlen(s) != 2 || s[0] < 'B' || s[0] > 'D' || s[1] < '0' || s[1] > '7')
		return -1;
	*port = s[0];
	*bit = s[1] - '0';
	return 0;
}

static void usage(FILE *f)
{
	fprintf(f,
		"usage: sphere-board FIRMWARE.elf --trace TRACE.bin [options]\n"
		"  --seconds S          simulated seconds to run (default 10)\n"
		"  --capture FILE       write the UART's bytes (device to host) to FILE\n"
		"  --pty                open the UART as a pseudo-terminal (prints its /dev/pts/N); implies --realtime\n"
		"  --realtime           pace simulated time to the wall clock\n"
		"  --stats FILE.json    write the run's figures as JSON\n"
		"  --rate HZ            the firmware's sample rate, for load and overrun figures (default 200)\n"
		"  --nack CHIP:T0:T1    CHIP (adxl345|itg3200|hmc5883l) does not answer from T0 to T1 s (T1 may be inf)\n"
		"  --stall T0:T1        the I2C bus is stalled (clock held low) from T0 to T1 s\n"
		"  --send FILE          bytes for the device's UART: lines \"SECONDS HEX HEX ...\"\n"
		"  --timing-pin PIN     the pin high during the MARG update (default B5 = D13)\n"
		"  --loop-pin PIN       a pin high during a whole sample period's work (optional)\n"
		"  --board NAME         board variant: aligned (default), sen10724, gy85, gy85-qmc\n"
		"  --noise              the chips' datasheet noise, turn-on offsets and gyro warm-up drift\n"
		"  --seed N             seed of the noise, the offsets, --clocks random and --glitch (default 1)\n"
		"  --clock-ppm CHIP:PPM a chip's oscillator off the Nano's crystal by PPM (repeatable)\n"
		"  --clocks random      every chip's oscillator off by a seeded amount within its datasheet's tolerance\n"
		"  --glitch RATE        transient faults, RATE a second on average (seeded): single NACKs, clock\n"
		"                       stretching, an AVR reset in the middle of a read (the chip then holds SDA)\n"
		"  --reset-mid-read T   reset the AVR (reset pin: EXTRF) at the first byte a chip sends after T s (the\n"
		"                       chip holds SDA)\n"
		"  --brownout T         the supply dips below the AVR's brown-out level at T s (not below its power-on\n"
		"                       threshold): brown-out reset (BORF, SRAM kept), the chips restart (repeatable)\n"
		"  --power-off T        the supply goes away at T s and comes back: power-on reset (PORF, SRAM lost),\n"
		"                       the chips restart (repeatable)\n"
		"  --reset-at T         the AVR resets at T s (reset pin: EXTRF), no chip left holding SDA (repeatable)\n"
		"  --sda-held           at power-up the magnetometer holds SDA low (left mid-read by a reset)\n"
		"  --host-stall T0:T1   the host stops reading from T0 to T1 s: the adapter's buffer fills, bytes drop\n"
		"  --adapter NAME       the USB-serial adapter between the UART and the host (capture, pty): ftdi (62-byte\n"
		"                       packets, 16 ms latency timer, 256-byte buffer) or ch340 (32-byte packets each 1 ms\n"
		"                       frame, 32-byte buffer); default none: bytes reach the host as they are sent\n"
		"  --latency-timer MS   the FTDI's latency timer as the driver sets it (default 16; the udev rule's 1); a\n"
		"                       host that asks for low latency on the pty gets 1 ms\n"
		"  --bootloader FILE.hex  a boot loader in front of the program (Intel HEX; the reset vector moves to its\n"
		"                       first address, as the Nano's BOOTRST/BOOTSZ fuses): build/bootloader-NAME.hex,\n"
		"                       NAME optiboot4 (the Nano's), atmegaboot (the old Nano's), optiboot8\n"
		"  --previous FILE.elf:T  run FILE.elf (a sketch flashed before) from power-up, and at T s flash the firmware\n"
		"                       over it and pulse the reset pin: the chips keep power and their registers, SRAM\n"
		"                       is kept (a reflash over a stick left as the earlier sketch set it)\n"
		"  --bus-pullup KOHM    the sensor board's pull-ups on SDA and SCL to its 3.3 V (default 4.7 kOhm)\n"
		"  --hang T0:T1         the program hangs from T0 to T1 s: no instruction outside an interrupt handler\n"
		"                       runs; interrupts, peripherals and the watchdog go on (a reset ends it)\n"
		"  --drdy-pin PIN       wire the HMC5883L's DRDY to PIN (e.g. D3; not wired on the sphere)\n"
		"  --capture-times FILE at each frame delimiter in the capture: u64 bytes captured so far, f64 simulated s\n"
		"  --host-log FILE      text: T0 (CLOCK_MONOTONIC ns at simulated 0), U (each frame's first byte and\n"
		"                       delimiter leaving the UART, simulated s), P (each pty write with delimiters:\n"
		"                       simulated s, CLOCK_MONOTONIC ns after the write, delimiters in it)\n"
		"  --simavr-i2c-timing  simavr's 1 us per I2C step (default: 9 SCL periods a byte at the TWBR rate)\n"
		"  --i2c-real-timing    (the default; kept for old scripts)\n"
		"  --simavr-twi-status  keep simavr 1.6's status 0x28/0x30 after SLA+W (default: the real 0x18/0x20)\n"
		"  -v                   log the bus (twice: every byte)\n");
}

/* simavr's uart_pty_connect() also points the fixed name /tmp/simavr-uart0 at its pty, replacing what another
   simulator (or anything else) had there. The board says its pty on stdout instead ("UART on /dev/pts/N"), so
   the name is put back as it was: another run's link restored, ours never left behind. */
static void pty_connect_without_link(uart_pty_t *pty)
{
	static const char link[] = "/tmp/simavr-uart0";
	char before[PATH_MAX], now[PATH_MAX];
	ssize_t nb = readlink(link, before, sizeof before - 1);
	uart_pty_connect(pty, '0');
	ssize_t nn = readlink(link, now, sizeof now - 1);
	if (nn > 0) {
		now[nn] = 0;
		if (strcmp(now, pty->port[0].slavename) == 0)
			unlink(link);
	}
	if (nb > 0) {
		before[nb] = 0;
		if (symlink(before, link) != 0)
			fprintf(stderr, "sphere-board: could not restore %s -> %s: %s\n", link, before, strerror(errno));
	}
}

int main(int argc, char **argv)
{
	pid_t parent0 = getppid();
	const char *trace_path = NULL, *capture_path = NULL, *stats_path = NULL, *send_path = NULL;
	double seconds = 10.0, rate_hz = 200.0;
	int use_pty = 0, realtime = 0, verbose = 0, real_i2c = 1, simavr_status = 0;
	const char *variant_name = "aligned";
	imperfections_t imp;
	memset(&imp, 0, sizeof imp);
	imp.seed = 1;
	int clocks_random = 0, sda_held = 0, n_brownouts = 0, n_stalls = 0, n_resets_mid = 0, n_resets_at = 0, n_power_offs = 0;
	double glitch_rate = 0, power_offs[MAX_FAULTS], brownouts[MAX_FAULTS], resets_mid[MAX_FAULTS], host_stalls[MAX_FAULTS][2], resets_at[MAX_FAULTS];
	const char *adapter = NULL, *times_path = NULL, *bootloader_path = NULL, *host_log_path = NULL;
	char previous_path[PATH_MAX] = "";
	double bus_pullup_kohm = 4.7;
	double reflash_s = -1;
	double hangs[MAX_FAULTS][2];
	int n_hangs = 0;
	uint32_t latency_timer_ms = 16; /* the FT232R latency timer as ftdi_sio leaves it (since Linux 4.x) */
	char tpin_port = 'B', lpin_port = 0, dpin_port = 0;
	int tpin_bit = 5, lpin_bit = 0, dpin_bit = 0;
	fault_t faults[MAX_FAULTS];
	int n_faults = 0;

	static struct option opts[] = {
		{"trace", required_argument, 0, 't'}, {"seconds", required_argument, 0, 's'},
		{"capture", required_argument, 0, 'c'}, {"pty", no_argument, 0, 'p'},
		{"realtime", no_argument, 0, 'r'}, {"stats", required_argument, 0, 'j'},
		{"rate", required_argument, 0, 'R'}, {"nack", required_argument, 0, 'N'},
		{"stall", required_argument, 0, 'S'}, {"send", required_argument, 0, 'i'},
		{"timing-pin", required_argument, 0, 'T'}, {"loop-pin", required_argument, 0, 'L'},
		{"i2c-real-timing", no_argument, 0, 'I'}, {"simavr-twi-status", no_argument, 0, 'Z'}, {"help", no_argument, 0, 'h'},
		{"board", required_argument, 0, 'B'}, {"noise", no_argument, 0, 'n'}, {"seed", required_argument, 0, 'e'},
		{"clock-ppm", required_argument, 0, 'P'}, {"clocks", required_argument, 0, 'C'},
		{"glitch", required_argument, 0, 'g'}, {"reset-mid-read", required_argument, 0, 'm'},
		{"brownout", required_argument, 0, 'b'}, {"sda-held", no_argument, 0, 'H'},
		{"host-stall", required_argument, 0, 'o'}, {"adapter", required_argument, 0, 'a'},
		{"latency-timer", required_argument, 0, 'Y'}, {"host-log", required_argument, 0, 'W'},
		{"simavr-i2c-timing", no_argument, 0, 'U'}, {"capture-times", required_argument, 0, 'X'},
		{"reset-at", required_argument, 0, 'A'}, {"drdy-pin", required_argument, 0, 'D'},
		{"power-off", required_argument, 0, 'O'}, {"bootloader", required_argument, 0, 'Q'},
		{"hang", required_argument, 0, 'G'}, {"previous", required_argument, 0, 'V'},
		{"bus-pullup", required_argument, 0, 'K'}, {0, 0, 0, 0}};
	int o;
	while ((o = getopt_long(argc, argv, "t:s:c:prj:vh", opts, NULL)) != -1) {
		switch (o) {
		case 't': trace_path = optarg; break;
		case 's': seconds = atof(optarg); break;
		case 'c': capture_path = optarg; break;
		case 'p': use_pty = 1; realtime = 1; break;
		case 'r': realtime = 1; break;
		case 'j': stats_path = optarg; break;
		case 'R': rate_hz = atof(optarg); break;
		case 'i': send_path = optarg; break;
		case 'v': verbose++; break;
		case 'I': real_i2c = 1; break;
		case 'U': real_i2c = 0; break;
		case 'X': times_path = optarg; break;
		case 'W': host_log_path = optarg; break;
		case 'D':
			if (parse_pin(optarg, &dpin_port, &dpin_bit)) { fprintf(stderr, "bad pin %s (e.g. D3)\n", optarg); return 2; }
			break;
		case 'B': variant_name = optarg; break;
		case 'n': imp.noise = 1; break;
		case 'e': imp.seed = strtoull(optarg, NULL, 0); break;
		case 'H': sda_held = 1; break;
		case 'g': glitch_rate = atof(optarg); break;
		case 'a':
			if (strcmp(optarg, "ftdi") && strcmp(optarg, "ch340")) { fprintf(stderr, "--adapter ftdi or ch340, not %s\n", optarg); return 2; }
			adapter = optarg;
			break;
		case 'Y': {
			char *end;
			long ms = strtol(optarg, &end, 10);
			if (*end || ms < 1 || ms > 255) { fprintf(stderr, "--latency-timer takes 1 to 255 ms (the FT232R's range), not %s\n", optarg); return 2; }
			latency_timer_ms = (uint32_t)ms;
			break;
		}
		case 'C':
			if (strcmp(optarg, "random")) { fprintf(stderr, "--clocks random (or --clock-ppm CHIP:PPM)\n"); return 2; }
			clocks_random = 1;
			break;
		case 'P': {
			char buf[64];
			snprintf(buf, sizeof buf, "%s", optarg);
			char *c = strchr(buf, ':');
			int chip = c ? (*c = 0, chip_by_name(buf)) : -1;
			if (chip < 0) { fprintf(stderr, "--clock-ppm CHIP:PPM with CHIP adxl345, itg3200 or hmc5883l\n"); return 2; }
			imp.ppm[chip] = atof(c + 1);
			break;
		}
		case 'b': case 'm': case 'A': case 'O':
			if ((o == 'b' ? n_brownouts : o == 'm' ? n_resets_mid : o == 'O' ? n_power_offs : n_resets_at) >= MAX_FAULTS) { fprintf(stderr, "too many faults of one kind (at most %d)\n", MAX_FAULTS); return 2; }
			if (o == 'b') brownouts[n_brownouts++] = atof(optarg);
			else if (o == 'm') resets_mid[n_resets_mid++] = atof(optarg);
			else if (o == 'O') power_offs[n_power_offs++] = atof(optarg);
			else resets_at[n_resets_at++] = atof(optarg);
			break;
		case 'o': {
			char *c = strchr(optarg, ':');
			if (!c || n_stalls >= MAX_FAULTS) { fprintf(stderr, "--host-stall T0:T1\n"); return 2; }
			host_stalls[n_stalls][0] = atof(optarg);
			host_stalls[n_stalls][1] = atof(c + 1);
			n_stalls++;
			break;
		}
		case 'Z': simavr_status = 1; break;
		case 'Q': bootloader_path = optarg; break;
		case 'K':
			bus_pullup_kohm = atof(optarg);
			if (!(bus_pullup_kohm > 0 && bus_pullup_kohm < 1000)) { fprintf(stderr, "--bus-pullup KOHM between 0 and 1000, not %s\n", optarg); return 2; }
			break;
		case 'V': {
			char *c = strrchr(optarg, ':');
			if (!c || c == optarg || (size_t)(c - optarg) >= sizeof previous_path || !(atof(c + 1) > 0)) {
				fprintf(stderr, "--previous FILE.elf:T with T > 0\n");
				return 2;
			}
			memcpy(previous_path, optarg, (size_t)(c - optarg));
			previous_path[c - optarg] = 0;
			reflash_s = atof(c + 1);
			break;
		}
		case 'G': {
			char *c = strchr(optarg, ':');
			if (!c || n_hangs >= MAX_FAULTS) { fprintf(stderr, "--hang T0:T1\n"); return 2; }
			hangs[n_hangs][0] = atof(optarg);
			hangs[n_hangs][1] = atof(c + 1);
			if (!(hangs[n_hangs][1] > hangs[n_hangs][0])) { fprintf(stderr, "--hang T0:T1 with T1 after T0, not %s\n", optarg); return 2; }
			n_hangs++;
			break;
		}
		case 'T':
			if (parse_pin(optarg, &tpin_port, &tpin_bit)) { fprintf(stderr, "bad pin %s (e.g. B5)\n", optarg); return 2; }
			break;
		case 'L':
			if (parse_pin(optarg, &lpin_port, &lpin_bit)) { fprintf(stderr, "bad pin %s (e.g. B4)\n", optarg); return 2; }
			break;
		case 'N': case 'S': {
			if (n_faults >= MAX_FAULTS) { fprintf(stderr, "too many faults of one kind (at most %d)\n", MAX_FAULTS); return 2; }
			fault_t *f = &faults[n_faults];
			char buf[128];
			snprintf(buf, sizeof buf, "%s", optarg);
			char *t0 = buf;
			f->chip = -1;
			if (o == 'N') {
				char *c = strchr(buf, ':');
				if (!c) { fprintf(stderr, "--nack CHIP:T0:T1\n"); return 2; }
				*c = 0;
				f->chip = chip_by_name(buf);
				if (f->chip < 0) { fprintf(stderr, "unknown chip %s (adxl345, itg3200, hmc5883l)\n", buf); return 2; }
				t0 = c + 1;
			}
			char *c2 = strchr(t0, ':');
			if (!c2) { fprintf(stderr, "a fault needs T0:T1\n"); return 2; }
			*c2 = 0;
			f->start_s = atof(t0);
			f->end_s = !strcmp(c2 + 1, "inf") ? INFINITY : atof(c2 + 1);
			f->active = 0;
			n_faults++;
			break;
		}
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (optind != argc - 1 || !trace_path) {
		usage(stderr);
		return 2;
	}
	const char *elf_path = argv[optind];

	trace_t trace;
	char err[512];
	if (trace_load(&trace, trace_path, err, sizeof err)) {
		fprintf(stderr, "sphere-board: %s\n", err);
		return 1;
	}

	elf_firmware_t fw;
	memset(&fw, 0, sizeof fw);
	if (access(elf_path, R_OK) || elf_read_firmware(elf_path, &fw)) {
		fprintf(stderr, "sphere-board: cannot read firmware %s\n", elf_path);
		return 1;
	}
	avr_t *avr = avr_make_mcu_by_name("atmega328p");
	if (!avr) {
		fprintf(stderr, "sphere-board: simavr has no atmega328p\n");
		return 1;
	}
	avr_init(avr);
	extint_level_poll_off(avr);
	avr->frequency = 16000000;
	avr->log = verbose > 3 ? LOG_TRACE : LOG_ERROR;
	elf_firmware_t prev;
	memset(&prev, 0, sizeof prev);
	if (previous_path[0] && (access(previous_path, R_OK) || elf_read_firmware(previous_path, &prev))) {
		fprintf(stderr, "sphere-board: cannot read the previous program %s\n", previous_path);
		return 1;
	}
	avr_load_firmware(avr, previous_path[0] ? &prev : &fw); /* the firmware itself goes in at the reflash */
	avr->frequency = 16000000; /* a Nano's crystal, whatever the ELF says */
	avr->sleep = no_sleep;     /* sleep is simulated time, never wall time */
	avr->reset = on_reset;     /* counts resets after power-up (the watchdog's); MCUSR as the datasheet says */
	if (avr->reset_flags.porf.reg)
		mcusr_addr = avr->reset_flags.porf.reg;
	mcu_mcusr_flags(avr, mcusr_addr); /* flags cleared by writing 0, not set by writing 1 (mcu.c) */
	mcu_eeprom_timing(avr);    /* EEPE busy for the datasheet's write time (mcu.c) */
	mcu_bus_init(avr, bus_pullup_kohm); /* the bus's levels: the AVR's pull-ups, a line driven high (mcu.c) */
	mcu_watchdog_init(avr);    /* the watchdog's interrupt and system reset mode as the datasheet says (mcu.c) */
	uint32_t boot_start = 0, boot_size = 0;
	if (bootloader_path) {
		char berr[256];
		if (mcu_load_bootloader(avr, bootloader_path, fw.flashsize, &boot_start, &boot_size, berr, sizeof berr)) {
			fprintf(stderr, "sphere-board: %s\n", berr);
			return 1;
		}
	}
	sram_power_on(avr, imp.seed, 0); /* power-up: SRAM holds whatever its cells came up with */
	avr->data[mcusr_addr] = MCUSR_PORF;
	mcusr_before = MCUSR_PORF;

	const board_variant_t *variant = board_variant_find(variant_name);
	if (!variant) {
		fprintf(stderr, "sphere-board: unknown board %s; one of", variant_name);
		for (const board_variant_t *v = board_variants; v->name; v++)
			fprintf(stderr, " %s", v->name);
		fprintf(stderr, "\n");
		return 2;
	}
	uint64_t glitch_rng = imp.seed * 0x9E3779B97F4A7C15ULL + 12345;
	if (clocks_random) { /* within each oscillator's tolerance (README: "Own clocks") */
		static const double tol_ppm[CHIP_COUNT] = {10000, 20000, 10000};
		uint64_t r = imp.seed * 0xD1B54A32D192ED03ULL + 777;
		for (int i = 0; i < CHIP_COUNT; i++) {
			r ^= r >> 12; r ^= r << 25; r ^= r >> 27;
			double u = (double)((r * 0x2545F4914F6CDD1DULL) >> 11) / 9007199254740992.0;
			imp.ppm[i] = (2 * u - 1) * tol_ppm[i];
		}
	}
	static board_t board;
	board_init(&board, avr, &trace, verbose, variant, &imp);
	board.on_fault = board_fault;
	if (dpin_port)
		board_wire_drdy(&board, avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(dpin_port), dpin_bit));
	the_board = &board;
	if (sda_held) {
		board.chip[CHIP_HMC5883L].holds_sda = 9;
		board.sda_held_events++;
		board_sda_update(&board);
		log_fault(0, "sda_held_at_power_up", CHIP_HMC5883L);
	}
	uart_out.avr = avr;
	if (host_log_path && !(uart_out.host_log = fopen(host_log_path, "w"))) {
		fprintf(stderr, "sphere-board: cannot write %s: %s\n", host_log_path, strerror(errno));
		return 1;
	}
	g_host_log = uart_out.host_log;
	if (times_path && !(uart_out.times = fopen(times_path, "wb"))) {
		fprintf(stderr, "sphere-board: cannot write %s: %s\n", times_path, strerror(errno));
		return 1;
	}
	uart_out.host_reading = 1;
	uart_out.adapter_buffer = adapter && !strcmp(adapter, "ch340") ? 32 : 256;
	if (adapter) {
		int ftdi = !strcmp(adapter, "ftdi");
		uart_out.packet = ftdi ? 62 : 32;
		uart_out.ftdi = ftdi;
		uart_out.latency_ms = latency_timer_ms;
		uart_out.latency_cycles = ftdi ? avr->frequency / 1000 * latency_timer_ms : 0; /* CH340: every 1 ms frame */
		avr_cycle_timer_register(avr, avr->frequency / 1000, adapter_timer, &uart_out);
	}

	/* UART 0 */
	uint32_t flags = 0;
	avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
	flags &= ~(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
	avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
	if (capture_path) {
		uart_out.capture = fopen(capture_path, "wb");
		if (!uart_out.capture) {
			fprintf(stderr, "sphere-board: cannot write %s: %s\n", capture_path, strerror(errno));
			return 1;
		}
	}
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_hook, &uart_out);
	uart_in_irq = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), xon_hook, NULL);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), xoff_hook, NULL);
	if (send_path) {
		if (load_sends(send_path))
			return 1;
		avr_cycle_timer_register(avr, avr->frequency / 10000, uart_send_timer, NULL);
	}
	static uart_pty_t pty;
	if (use_pty) {
		uart_pty_init(avr, &pty);
		pty_connect_without_link(&pty);
		/* the host's side (the adapter's packets, or each byte) is written by host_deliver(), not simavr's thread,
		 * which keeps reading what the host sends */
		avr_unconnect_irq(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), pty.irq + IRQ_UART_PTY_BYTE_IN);
		/* and what the host sends passes the rate check (pty_to_avr_hook) on its way to the AVR */
		avr_unconnect_irq(pty.irq + IRQ_UART_PTY_BYTE_OUT, uart_in_irq);
		avr_irq_register_notify(pty.irq + IRQ_UART_PTY_BYTE_OUT, pty_to_avr_hook, &uart_out);
		uart_out.pty_fd = pty.port[0].s;
		tcgetattr(uart_out.pty_fd, &uart_out.untouched);
		fcntl(uart_out.pty_fd, F_SETFL, fcntl(uart_out.pty_fd, F_GETFL) | O_NONBLOCK);
		uart_out.realtime = realtime;
		printf("sphere-board: UART on %s\n", pty.port[0].slavename);
		fflush(stdout);
	}

	/* timing pins */
	avr_cycle_count_t period = (avr_cycle_count_t)llround(avr->frequency / rate_hz);
	tm_update.board = tm_loop.board = &board;
	tm_update.period_cycles = tm_loop.period_cycles = period;
	board.start_armed = 1;
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(tpin_port), tpin_bit), pin_hook, &tm_update);
	if (lpin_port) {
		have_loop_pin = 1;
		tm_loop.is_loop_pin = 1;
		tm_loop.period_cycles = 4 * period;
		avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(lpin_port), lpin_bit), pin_hook, &tm_loop);
	}

	for (int v = 1; v < N_VECTORS; v++) {
		avr_irq_t *irq = avr_get_interrupt_irq(avr, (uint8_t)v);
		if (irq)
			avr_irq_register_notify(irq + AVR_INT_IRQ_RUNNING, vector_hook, (void *)(intptr_t)v);
	}

	void *twi = find_io(avr, "twi");
	board.twi = twi;
	board.real_timing = real_i2c;
	board.fix_status = !simavr_status;
	if (!twi && n_faults)
		fprintf(stderr, "sphere-board: warning: no TWI module found, bus stalls cannot be simulated\n");

	signal(SIGINT, on_signal);
	signal(SIGTERM, on_signal);
#ifdef __linux__
	/* Stop (as on SIGTERM: stats written, pty closed) when whoever started us goes: `sphere sim` or the
	 * daemon killed or crashed would otherwise leave the board holding its pty and a core until its
	 * --seconds are over. parent0 catches a parent that went before the prctl. */
	prctl(PR_SET_PDEATHSIG, SIGTERM);
	if (getppid() != parent0)
		stop_requested = 1;
#endif

	avr_cycle_count_t end_cycle = (avr_cycle_count_t)(seconds * avr->frequency);
	avr_cycle_count_t next_check = 0;
	const avr_cycle_count_t check_every = avr->frequency / 1000; /* 1 ms */
	double wall0 = wall_now(), cpu0 = cpu_now();
	board_wall0 = wall0;
	if (uart_out.host_log) {
		fprintf(uart_out.host_log, "T0 %lld\n", (long long)llround(wall0 * 1e9));
		setvbuf(uart_out.host_log, NULL, _IOFBF, 1 << 16);
	}
	int stall = 0, state = cpu_Running;
	double next_glitch = glitch_rate > 0 ? 0.5 : INFINITY;
	int brown_i = 0, reset_i = 0, reset_at_i = 0, power_off_i = 0;
	uint32_t resets_seen = resets;
	int hang_i = 0, hang_wanted = 0, hanging = 0;
	while (avr->cycle < end_cycle && !stop_requested) {
		if (hanging) {
			mcu_hang_step(avr);
		} else {
			state = avr_run(avr);
			if (state == cpu_Done || state == cpu_Crashed)
				break;
			if (hang_wanted && mcu_hang_begin(avr)) {
				hang_wanted = 0;
				hanging = 1;
				log_fault(board_time_s(&board), "hang_start", -1);
			}
		}
		if (!avr->pc && avr->interrupts.running_ptr) { /* left an interrupt handler for the reset vector (mcu.c) */
			mcu_at_reset_vector(avr);
			if (hanging) { /* the program restarted itself: that ends its hang */
				hanging = 0;
				log_fault(board_time_s(&board), "hang_end_by_restart", -1);
			}
		}
		mcusr_before = avr->data[mcusr_addr];
		if (mcu_watchdog_poll(avr)) {
			log_fault(board_time_s(&board), "watchdog_unserved", -1);
			watchdog_reset_avr(avr);
		}
		if (resets != resets_seen) { /* simavr's reset cancelled every cycle timer: ours start again */
			resets_seen = resets;
			if (hanging || hang_wanted) { /* a reset ends a hang */
				hanging = hang_wanted = 0;
				log_fault(board_time_s(&board), "hang_end_by_reset", -1);
			}
			board_restart_timers(&board);
			extint_level_poll_off(avr);
			if (adapter) { /* the adapter is not reset with the AVR, but simavr cancelled its timer */
				avr_cycle_timer_cancel(avr, adapter_timer, &uart_out);
				avr_cycle_timer_register(avr, avr->frequency / 1000, adapter_timer, &uart_out);
			}
			if (send_path) {
				avr_cycle_timer_cancel(avr, uart_send_timer, NULL);
				avr_cycle_timer_register(avr, avr->frequency / 10000, uart_send_timer, NULL);
			}
		}
		if ((stall || board.chip[0].holds_sda || board.chip[1].holds_sda || board.chip[2].holds_sda) && twi)
			hold_twi(avr, twi); /* a held clock, or SDA held low: the TWI cannot finish a step */
		if (board.reset_pending) {
			board.reset_pending = 0;
			log_fault(board_time_s(&board), "reset_mid_read", board.cur_chip);
			reset_avr(avr, MCUSR_EXTRF, imp.seed);
		}
		if (avr->cycle >= next_check) {
			next_check = avr->cycle + check_every;
			double t = (double)avr->cycle / avr->frequency;
			for (int i = 0; i < n_stalls; i++) {
				int stalled_host = t >= host_stalls[i][0] && t < host_stalls[i][1];
				if (stalled_host && uart_out.host_reading) {
					uart_out.host_reading = 0;
					uart_out.buffered = 0;
					log_fault(t, "host_stall", -1);
				} else if (!stalled_host && !uart_out.host_reading && t >= host_stalls[i][1] && t < host_stalls[i][1] + 0.002) {
					uart_out.host_reading = 1;
					log_fault(t, "host_reads", -1);
				}
			}
			while (brown_i < n_brownouts && t >= brownouts[brown_i]) {
				brown_i++;
				log_fault(t, "brownout", -1);
				reset_avr(avr, MCUSR_BORF, imp.seed);
				board_power_cycle(&board);
			}
			while (power_off_i < n_power_offs && t >= power_offs[power_off_i]) {
				power_off_i++;
				log_fault(t, "power_off", -1);
				reset_avr(avr, MCUSR_PORF, imp.seed);
				board_power_cycle(&board);
			}
			while (reset_at_i < n_resets_at && t >= resets_at[reset_at_i]) {
				reset_at_i++;
				log_fault(t, "reset", -1);
				plain_reset = 1;
				reset_avr(avr, MCUSR_EXTRF, imp.seed);
				plain_reset = 0;
			}
			if (reflash_s > 0 && t >= reflash_s) { /* the programmer rewrote the application section */
				reflash_s = -1;
				memset(avr->flash, 0xFF, boot_start ? boot_start : avr->flashend + 1u);
				avr_loadcode(avr, fw.flash, fw.flashsize, fw.flashbase);
				log_fault(t, "reflash", -1);
				plain_reset = 1;
				reset_avr(avr, MCUSR_EXTRF, imp.seed);
				plain_reset = 0;
			}
			while (hang_i < n_hangs && t >= hangs[hang_i][0]) {
				if (t < hangs[hang_i][1])
					hang_wanted = 1;
				hang_i++;
			}
			if ((hanging || hang_wanted) && hang_i > 0 && t >= hangs[hang_i - 1][1]) {
				if (hanging)
					log_fault(t, "hang_end", -1);
				hanging = hang_wanted = 0;
			}
			while (reset_i < n_resets_mid && t >= resets_mid[reset_i]) {
				reset_i++;
				board.reset_on_read = 1;
			}
			while (t >= next_glitch) {
				double u = 0;
				glitch_rng ^= glitch_rng >> 12; glitch_rng ^= glitch_rng << 25; glitch_rng ^= glitch_rng >> 27;
				u = (double)((glitch_rng * 0x2545F4914F6CDD1DULL) >> 11) / 9007199254740992.0;
				int kind = (int)(u * 20) ;   /* 0..9 NACK, 10..17 stretch, 18..19 reset mid-read */
				int chip = (int)(u * 60) % 3;
				if (kind < 10)
					board.chip[chip].glitch_nack = 1;
				else if (kind < 18)
					board.stretch_cycles = avr->frequency / 10000 * (1 + (int)(u * 977) % 20); /* 0.1..2 ms */
				else
					board.reset_on_read = 1;
				glitch_rng ^= glitch_rng >> 12; glitch_rng ^= glitch_rng << 25; glitch_rng ^= glitch_rng >> 27;
				u = (double)((glitch_rng * 0x2545F4914F6CDD1DULL) >> 11) / 9007199254740992.0;
				next_glitch += -log(1.0 - u) / glitch_rate; /* Poisson arrivals */
			}
			int stall_now = 0;
			for (int i = 0; i < n_faults; i++) {
				fault_t *f = &faults[i];
				int on = t >= f->start_s && t < f->end_s;
				if (f->chip < 0) {
					stall_now |= on;
				} else if (on != f->active) {
					board.chip[f->chip].nack = on;
					log_fault(t, on ? "nack_start" : "nack_end", f->chip);
					if (verbose)
						fprintf(stderr, "[%.3f] %s %s\n", t, board.chip[f->chip].name, on ? "stops answering" : "answers again");
				}
				f->active = on;
			}
			if (stall_now != stall) {
				if (verbose)
					fprintf(stderr, "[%.3f] bus %s\n", t, stall_now ? "stalled" : "released");
				if (!stall_now) {
					board.bus_busy = 0;
					board.cur_chip = -1;
				}
				log_fault(t, stall_now ? "stall_start" : "stall_end", -1);
				stall = stall_now;
				board.stalled = stall;
			}
			if (realtime) {
				double ahead = t - (wall_now() - wall0);
				if (ahead > 0.002) {
					struct timespec ts = {(time_t)ahead, (long)((ahead - floor(ahead)) * 1e9)};
					nanosleep(&ts, NULL);
				}
			}
		}
	}
	double wall = wall_now() - wall0, cpu = cpu_now() - cpu0;
	double sim_s = (double)avr->cycle / avr->frequency;
	if (tx_n)
		tx_flight_timer(avr, (avr_cycle_count_t)-1, &uart_out); /* the frame on the line when the run ended */
	if (uart_out.pending)
		adapter_flush(&uart_out); /* what the adapter still held */
	/* a full or read-only disk: say so and fail, never leave a short file behind silently */
	if (uart_out.capture && (ferror(uart_out.capture) | fclose(uart_out.capture))) {
		fprintf(stderr, "sphere-board: cannot write %s: %s\n", capture_path, strerror(errno ? errno : EIO));
		return 1;
	}
	if (uart_out.host_log && (ferror(uart_out.host_log) | fclose(uart_out.host_log))) {
		fprintf(stderr, "sphere-board: cannot write %s: %s\n", host_log_path, strerror(errno ? errno : EIO));
		return 1;
	}
	if (uart_out.times && (ferror(uart_out.times) | fclose(uart_out.times))) {
		fprintf(stderr, "sphere-board: cannot write %s: %s\n", times_path, strerror(errno ? errno : EIO));
		return 1;
	}
	/* no uart_pty_stop(): it signals its thread with SIGINT, which our handler catches, and then waits
	 * for it forever; leaving main ends the thread with the process */

	if (state == cpu_Crashed)
		fprintf(stderr, "sphere-board: the AVR crashed at %.6f s (pc 0x%04x)\n", sim_s, avr->pc);

	vec_t *lv = have_loop_pin ? &tm_loop.update : (loop_tick.n ? &loop_tick : &tm_loop.update);
	size_t loop_n = lv->n;
	uint32_t loop_med = 0, upd_med = 0;
	FILE *sf = NULL;
	if (stats_path) {
		sf = fopen(stats_path, "w");
		if (!sf) {
			fprintf(stderr, "sphere-board: cannot write %s\n", stats_path);
			return 1;
		}
		fprintf(sf, "{\n");
		stats3(sf, "cycles_per_update", &tm_update.update);
		stats3(sf, "cycles_per_loop", lv);
	} else {
		if (tm_update.update.n) qsort(tm_update.update.v, tm_update.update.n, 4, cmp_u32);
		if (lv->n) qsort(lv->v, lv->n, 4, cmp_u32);
	}
	if (tm_update.update.n) upd_med = tm_update.update.v[tm_update.update.n / 2];
	if (loop_n) loop_med = lv->v[loop_n / 2];
	double load = loop_n ? (double)loop_med / period : (tm_update.update.n ? (double)upd_med / period : 0);
	double load_max = loop_n ? (double)lv->v[loop_n - 1] / period : 0;
	uint32_t i2c_errors = board.i2c_errors + stalled_steps;
	if (sf) {
		fprintf(sf, "  \"cpu_load\": %.4f,\n", load);
		fprintf(sf, "  \"cpu_load_max\": %.4f,\n", load_max);
		fprintf(sf, "  \"cpu_load_basis\": \"%s\",\n",
			have_loop_pin ? "median loop-pin pulse / sample period"
			: lv == &loop_tick ? "median (sample clock interrupt entry .. end of the MARG update) / sample period"
			: loop_n ? "median (first I2C START of the period .. end of the MARG update) / sample period"
			: "median MARG update / sample period (no loop measured)");
		if (real_i2c)
			fprintf(sf, "  \"i2c_timing_note\": \"--i2c-real-timing: each TWI byte step stretched to 9 SCL periods at the firmware's TWBR rate (the START and STOP conditions are not), so the loop figures approximate the real bus; the MARG update cycles are exact\",\n");
		else
		fprintf(sf, "  \"i2c_timing_note\": \"simavr 1.6 clocks the TWI at one SCL period per microsecond (9 us a byte) whatever TWBR says, so I2C time in the loop figures is not real 400 kHz time (22.5 us a byte); the MARG update cycles are exact\",\n");
		fprintf(sf, "  \"sample_rate_hz\": %.3f,\n", rate_hz);
		fprintf(sf, "  \"sample_clock_vector\": %d,\n", tick_vector);
		fprintf(sf, "  \"period_cycles\": %llu,\n", (unsigned long long)period);
		fprintf(sf, "  \"overruns\": %u,\n", tm_update.overruns);
		fprintf(sf, "  \"updates\": %u,\n", tm_update.updates);
		fprintf(sf, "  \"timing_pin_long_pulses\": %u,\n", tm_update.long_pulses);
		fprintf(sf, "  \"frames_sent\": %u,\n", uart_out.frames);
		fprintf(sf, "  \"uart_bytes\": %llu,\n", (unsigned long long)uart_out.bytes);
		fprintf(sf, "  \"i2c_transactions\": %u,\n", board.transactions);
		fprintf(sf, "  \"i2c_errors\": %u,\n", i2c_errors);
		fprintf(sf, "  \"i2c_starts\": %u,\n", board.starts);
		fprintf(sf, "  \"i2c_address_nacks\": %u,\n", board.addr_nacks);
		fprintf(sf, "  \"i2c_stalled_steps\": %u,\n", stalled_steps);
		fprintf(sf, "  \"chip_nacks\": {\"adxl345\": %u, \"itg3200\": %u, \"hmc5883l\": %u},\n",
			board.chip[0].nacked, board.chip[1].nacked, board.chip[2].nacked);
		fprintf(sf, "  \"adxl345_events\": {\"single_tap\": %u, \"double_tap\": %u, \"free_fall\": %u},\n",
			board.events_single_tap, board.events_double_tap, board.events_free_fall);
		fprintf(sf, "  \"bootloader\": %s%s%s,\n", bootloader_path ? "\"" : "", bootloader_path ? bootloader_path : "null", bootloader_path ? "\"" : "");
		fprintf(sf, "  \"bootloader_start\": %u,\n  \"bootloader_bytes\": %u,\n", boot_start, boot_size);
		fprintf(sf, "  \"eeprom_writes\": %u,\n", mcu_eeprom_writes);
		fprintf(sf, "  \"bus\": {\"avr_pullup_events\": %u, \"first_avr_pullup_s\": %.6f, \"driven_high_events\": %u, "
			"\"first_driven_high_s\": %.6f, \"idle_high_v_max\": %.3f, \"limit_v\": %.2f, \"over_limit\": %s, "
			"\"sensor_pullup_kohm\": %.2f, \"scl_khz\": %.1f, \"scl_low_us\": %.4f, \"scl_low_ok\": %s},\n",
			mcu_bus.pullup_events, mcu_bus.first_pullup_s, mcu_bus.driven_high_events, mcu_bus.first_driven_high_s,
			mcu_bus.idle_high_v_max ? mcu_bus.idle_high_v_max : 3.3, mcu_bus.limit_v,
			mcu_bus.idle_high_v_max > mcu_bus.limit_v ? "true" : "false", bus_pullup_kohm,
			mcu_bus.scl_low_us_min < 1e9 ? mcu_bus.scl_khz : 0.0, mcu_bus.scl_low_us_min < 1e9 ? mcu_bus.scl_low_us_min : 0.0,
			/* t_LOW: 1.3 us in fast mode (above 100 kHz), 4.7 us in standard mode */
			mcu_bus.scl_low_us_min < 1e9 && mcu_bus.scl_low_us_min >= (mcu_bus.scl_khz > 100.05 ? 1.3 : 4.7) ? "true" : "false");
		fprintf(sf, "  \"adxl345_data_age_ms\": {\"max\": %.3f, \"first_after_start\": [", board.adxl_age_max_ms);
		for (int i = 0; i < board.adxl_first_ages; i++)
			fprintf(sf, "%s%.3f", i ? ", " : "", board.adxl_first_age_ms[i]);
		fprintf(sf, "]},\n");
		fprintf(sf, "  \"watchdog_interrupts\": %u,\n", mcu_watchdog_interrupts);
		fprintf(sf, "  \"simulated_seconds\": %.6f,\n", sim_s);
		fprintf(sf, "  \"wall_seconds\": %.3f,\n", wall);
		fprintf(sf, "  \"speed\": %.3f,\n", wall > 0 ? sim_s / wall : 0);
		fprintf(sf, "  \"cpu_seconds\": %.3f,\n", cpu);
		fprintf(sf, "  \"speed_cpu\": %.3f,\n", cpu > 0 ? sim_s / cpu : 0);
		fprintf(sf, "  \"resets\": %u,\n", resets);
		fprintf(sf, "  \"board\": \"%s\",\n  \"magnetometer\": \"%s\",\n  \"noise\": %s,\n  \"seed\": %llu,\n",
			variant->name, board.chip[CHIP_HMC5883L].name, imp.noise ? "true" : "false", (unsigned long long)imp.seed);
		fprintf(sf, "  \"clock_ppm\": {\"adxl345\": %.1f, \"itg3200\": %.1f, \"hmc5883l\": %.1f},\n",
			board.imp.ppm[0], board.imp.ppm[1], board.imp.ppm[2]);
		fprintf(sf, "  \"i2c_real_timing\": %s,\n", real_i2c ? "true" : "false");
		fprintf(sf, "  \"glitches\": {\"nacks\": %u, \"clock_stretches\": %u, \"sda_held\": %u},\n",
			board.glitch_nacks, board.clock_stretches, board.sda_held_events);
		fprintf(sf, "  \"hmc5883l_measurements\": %u,\n  \"hmc5883l_held_by_lock\": %u,\n",
			board.hmc.measurements, board.hmc.dropped_locked);
		fprintf(sf, "  \"host_dropped_bytes\": %llu,\n", (unsigned long long)uart_out.host_dropped);
		fprintf(sf, "  \"garbled_bytes_to_host\": %llu,\n  \"garbled_bytes_to_device\": %llu,\n",
			(unsigned long long)uart_out.garbled_out, (unsigned long long)uart_out.garbled_in);
		fprintf(sf, "  \"adapter\": %s%s%s,\n", adapter ? "\"" : "", adapter ? adapter : "null", adapter ? "\"" : "");
		fprintf(sf, "  \"faults\": [");
		for (size_t i = 0; i < n_fault_log; i++)
			fprintf(sf, "%s{\"t\": %.6f, \"kind\": \"%s\", \"chip\": %s%s%s}", i ? ", " : "", fault_log[i].t_s,
				fault_log[i].kind, fault_log[i].chip >= 0 ? "\"" : "",
				fault_log[i].chip >= 0 ? board.chip[fault_log[i].chip].name : "null", fault_log[i].chip >= 0 ? "\"" : "");
		fprintf(sf, "],\n");
		fprintf(sf, "  \"crashed\": %s\n", state == cpu_Crashed ? "true" : "false");
		fprintf(sf, "}\n");
		if (ferror(sf) | fclose(sf)) {
			fprintf(stderr, "sphere-board: cannot write %s: %s\n", stats_path, strerror(errno ? errno : EIO));
			return 1;
		}
	}
	fprintf(stderr,
		"sphere-board: %.3f simulated s in %.3f wall s (x%.2f); %u MARG updates, median %u cycles; "
		"%u frames, %llu bytes; %u I2C transactions, %u errors\n",
		sim_s, wall, wall > 0 ? sim_s / wall : 0, tm_update.updates, upd_med, uart_out.frames,
		(unsigned long long)uart_out.bytes, board.transactions, i2c_errors);
	return state == cpu_Crashed ? 3 : 0;
}
