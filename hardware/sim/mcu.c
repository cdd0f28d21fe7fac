/* The ATmega328P itself where the board adds to simavr 1.6 or corrects it to the datasheet (Atmel ATmega328P,
 * DS40002061A): the boot loader, the EEPROM's write time, the watchdog, a hung program.
 * SPDX-License-Identifier: GPL-3.0-or-later (links simavr, GPL-3.0). */
#include "mcu.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "avr_eeprom.h"
#include "avr_watchdog.h"
#include "sim_cycle_timers.h"
#include "sim_interrupts.h"
#include "sim_io.h"
#include "sim_time.h"

static avr_io_t *io_by_kind(avr_t *avr, const char *kind)
{
	for (avr_io_t *io = avr->io_port; io; io = io->next)
		if (io->kind && !strcmp(io->kind, kind))
			return io;
	return NULL;
}

/* ---------------------------------------------------------------- boot loader
 * Datasheet "Boot Loader Support – Read-While-Write Self-Programming": with the BOOTRST fuse programmed the
 * reset vector is the first address of the boot section, whose size the BOOTSZ fuses set (Table "Boot Size
 * Configuration": 256 words from 0x3F00 (byte 0x7E00) ... 2048 words from 0x3800 (byte 0x7000)). The Nano's
 * fuses put it where its boot loader starts: high fuse 0xDA (1024 words, byte 0x7800) for the old ATmegaBOOT,
 * 0xDE (256 words, 0x7E00) for Optiboot. The program's interrupt vectors stay at 0 (IVSEL is 0 after reset). */
/* Intel HEX: data records (00) with extended segment (02) and linear (04) addresses; the start address records
 * (03, 05) say nothing the reset vector does not. Every record's checksum is checked. */
static int read_hex(const char *path, uint8_t *image, uint8_t *used, uint32_t size, char *err, size_t errlen)
{
	FILE *f = fopen(path, "r");
	if (!f) {
		snprintf(err, errlen, "cannot read the boot loader %s", path);
		return -1;
	}
	char line[600];
	uint32_t base = 0;
	int n = 0, rc = -1;
	while (fgets(line, sizeof line, f)) {
		n++;
		if (line[0] != ':')
			continue;
		uint8_t b[260];
		int len = 0;
		unsigned v;
		for (const char *c = line + 1; len < (int)sizeof b && sscanf(c, "%2x", &v) == 1 && c[1] && c[1] != '\n'; c += 2)
			b[len++] = (uint8_t)v;
		uint8_t sum = 0;
		for (int i = 0; i < len; i++)
			sum = (uint8_t)(sum + b[i]);
		if (len < 5 || len != b[0] + 5 || sum) {
			snprintf(err, errlen, "%s line %d: not an Intel HEX record (length or checksum)", path, n);
			goto out;
		}
		uint32_t addr = base + (uint32_t)(b[1] << 8 | b[2]);
		if (b[3] == 0x00) {
			if (addr + b[0] > size) {
				snprintf(err, errlen, "%s line %d: address 0x%x is outside the flash", path, n, addr);
				goto out;
			}
			memcpy(image + addr, b + 4, b[0]);
			memset(used + addr, 1, b[0]);
		} else if (b[3] == 0x01) {
			rc = 0;
			goto out;
		} else if (b[3] == 0x02) {
			base = (uint32_t)(b[4] << 8 | b[5]) << 4;
		} else if (b[3] == 0x04) {
			base = (uint32_t)(b[4] << 8 | b[5]) << 16;
		}
	}
	snprintf(err, errlen, "%s: no end-of-file record", path);
out:
	fclose(f);
	return rc;
}

int mcu_load_bootloader(avr_t *avr, const char *path, uint32_t app_bytes, uint32_t *start, uint32_t *size,
			char *err, size_t errlen)
{
	uint32_t flash = avr->flashend + 1u;
	uint8_t *image = malloc(flash), *used = calloc(flash, 1);
	if (!image || !used || read_hex(path, image, used, flash, err, errlen)) {
		free(image);
		free(used);
		return -1;
	}
	uint32_t lo = flash, hi = 0;
	for (uint32_t a = 0; a < flash; a++)
		if (used[a]) {
			if (a < lo) lo = a;
			hi = a + 1;
		}
	int rc = -1;
	if (lo == flash)
		snprintf(err, errlen, "the boot loader %s holds no data", path);
	else if (lo < app_bytes)
		snprintf(err, errlen, "the program (%u bytes) overlaps the boot loader at 0x%04x", app_bytes, lo);
	else
		rc = 0;
	if (!rc)
		for (uint32_t a = lo; a < hi; a++)
			if (used[a])
				avr->flash[a] = image[a];
	free(image);
	free(used);
	if (rc)
		return rc;
	avr->reset_pc = lo;
	avr->pc = lo;
	*start = lo;
	*size = hi - lo;
	return 0;
}

/* ---------------------------------------------------------------- MCUSR
 * Datasheet "MCUSR – MCU Status Register": each flag "is reset by a Power-on Reset, or by writing a logic zero to
 * the flag"; writing a one leaves it as it is (bits 7..4 are reserved and read zero). simavr 1.6 stores the value
 * written, so Optiboot 8's `MCUSR = ~(1 << WDRF)` (clear WDRF, keep the rest) set PORF, EXTRF and BORF. */
static void mcusr_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	avr->data[addr] = (uint8_t)(avr->data[addr] & v & 0x0F);
}

void mcu_mcusr_flags(avr_t *avr, uint16_t mcusr_addr)
{
	avr->io[AVR_DATA_TO_IO(mcusr_addr)].w.c = mcusr_write;
	avr->io[AVR_DATA_TO_IO(mcusr_addr)].w.param = NULL;
}

/* ---------------------------------------------------------------- EEPROM
 * Datasheet "EEPROM Data Memory" and "EECR – The EEPROM Control Register": writing EEMPE opens a window of
 * four clock cycles in which writing EEPE starts the operation EEPM selects (Table "EEPROM Mode Bits": 00
 * erase and write 3.4 ms, 01 erase only 1.8 ms, 10 write only 1.8 ms); EEPE stays one until the operation
 * is done, and while it is, "it is neither possible to read the EEPROM, nor to change the EEAR Register",
 * and the EEPM bits cannot be changed. EERE reads the byte at EEAR into EEDR at once (the CPU halts four
 * cycles, not modelled). simavr 1.6 writes the byte and clears EEPE in the same instruction, so a program's
 * busy wait takes no time. The model latches address and data when the operation starts and writes the cell
 * when it ends; EEAR written meanwhile does not change the operation. */
enum { EECR = 0x3F, EEDR = 0x40, EEARL = 0x41, EEARH = 0x42 };
enum { EERE = 1, EEPE = 2, EEMPE = 4, EERIE = 8, EEPM = 0x30 };
static avr_eeprom_t *eeprom;
static struct {
	int busy;
	uint16_t addr;
	uint8_t data, mode;
} ee_op;
uint32_t mcu_eeprom_writes;

static avr_cycle_count_t ee_mpe_clear(avr_t *avr, avr_cycle_count_t when, void *param)
{
	(void)when; (void)param;
	avr->data[EECR] &= (uint8_t)~EEMPE;
	return 0;
}

static avr_cycle_count_t ee_done(avr_t *avr, avr_cycle_count_t when, void *param)
{
	(void)when; (void)param;
	uint8_t *cell = &eeprom->eeprom[ee_op.addr];
	if (ee_op.mode == 0)
		*cell = ee_op.data;
	else if (ee_op.mode == 1)
		*cell = 0xFF;
	else
		*cell &= ee_op.data; /* write only: programs zeros into an erased cell */
	ee_op.busy = 0;
	mcu_eeprom_writes++;
	avr->data[EECR] &= (uint8_t)~EEPE;
	if (avr->data[EECR] & EERIE)
		avr_raise_interrupt(avr, &eeprom->ready);
	return 0;
}

static void ee_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	uint8_t old = avr->data[addr];
	uint8_t now = (uint8_t)((old & (EEPE | EEMPE)) | (v & EERIE));
	now |= ee_op.busy ? (old & EEPM) : (v & EEPM);
	if ((v & EEMPE) && !(old & EEMPE)) {
		now |= EEMPE;
		avr_cycle_timer_register(avr, 4, ee_mpe_clear, NULL);
	}
	if ((v & EEPE) && (old & EEMPE) && !ee_op.busy) {
		ee_op.busy = 1;
		ee_op.addr = (uint16_t)((avr->data[EEARL] | (avr->data[EEARH] << 8)) & (eeprom->size - 1));
		ee_op.data = avr->data[EEDR];
		ee_op.mode = (uint8_t)((now & EEPM) >> 4);
		now = (uint8_t)((now | EEPE) & ~EEMPE);
		avr_cycle_timer_cancel(avr, ee_mpe_clear, NULL);
		avr_cycle_timer_register_usec(avr, ee_op.mode == 0 ? 3400 : 1800, ee_done, NULL);
	}
	if ((v & EERE) && !ee_op.busy) {
		uint16_t a = (uint16_t)((avr->data[EEARL] | (avr->data[EEARH] << 8)) & (eeprom->size - 1));
		avr->data[EEDR] = eeprom->eeprom[a];
	}
	avr->data[addr] = now;
}

void mcu_eeprom_timing(avr_t *avr)
{
	eeprom = (avr_eeprom_t *)io_by_kind(avr, "eeprom");
	if (!eeprom)
		return;
	avr->io[AVR_DATA_TO_IO(EECR)].w.c = ee_write;
	avr->io[AVR_DATA_TO_IO(EECR)].w.param = NULL;
}

/* ---------------------------------------------------------------- watchdog
 * Datasheet "Watchdog Timer" and "WDTCSR – Watchdog Timer Control Register", where simavr 1.6 differs:
 * (1) "WDE is overridden by WDRF in MCUSR. This means that WDE is always set when WDRF is set." After any
 *     reset that leaves WDRF set (an external or brown-out reset while a watchdog reset's flag is still
 *     there: only a power-on clears it unless the program does) the watchdog runs in system reset mode at
 *     its reset prescaler (WDP = 0: 2K cycles of the 128 kHz oscillator, 16 ms). simavr starts it only after
 *     its own watchdog reset.
 * (2) Interrupt and system reset mode (WDE and WDIE): "The first time-out in the Watchdog Timer will set
 *     WDIF. Executing the corresponding interrupt vector will clear WDIE and WDIF automatically by hardware
 *     (the Watchdog goes to System Reset Mode)." and "If the interrupt is not executed before the next
 *     time-out, a System Reset will be applied." simavr raises the interrupt again at every time-out while
 *     WDIE is set and never resets then. */
static avr_watchdog_t *wdt;
static int wdt_unserved;  /* its interrupt raised and the vector not executed yet */
static int wdt_reset_due;
static int (*wdt_ioctl)(struct avr_io_t *io, uint32_t ctl, void *param);
uint32_t mcu_watchdog_interrupts;

/* the time-out after the one that raised the interrupt (simavr raises its interrupt once and does not count on) */
static avr_cycle_count_t wdt_next_timeout(avr_t *avr, avr_cycle_count_t when, void *param)
{
	(void)when; (void)param;
	if (wdt_unserved && avr_regbit_get(avr, wdt->wde))
		wdt_reset_due = 1;
	return 0;
}

static void wdt_pending(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq; (void)param;
	if (!value || wdt_unserved)
		return;
	mcu_watchdog_interrupts++;
	wdt_unserved = 1;
	avr_cycle_timer_register(wdt->io.avr, wdt->cycle_count, wdt_next_timeout, NULL);
}

static void wdt_running(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq; (void)param;
	if (value) {
		wdt_unserved = 0;
		avr_cycle_timer_cancel(wdt->io.avr, wdt_next_timeout, NULL);
	}
}

/* WDR restarts the count ("Watchdog Timer": "the WDR - Watchdog Reset - instruction ... restarts the timer") */
static int wdt_ioctl_wdr(struct avr_io_t *io, uint32_t ctl, void *param)
{
	if (ctl == AVR_IOCTL_WATCHDOG_RESET && wdt_unserved)
		avr_cycle_timer_register(wdt->io.avr, wdt->cycle_count, wdt_next_timeout, NULL);
	return wdt_ioctl ? wdt_ioctl(io, ctl, param) : -1;
}

void mcu_watchdog_init(avr_t *avr)
{
	wdt = (avr_watchdog_t *)io_by_kind(avr, "watchdog");
	if (!wdt)
		return;
	avr_irq_register_notify(wdt->watchdog.irq + AVR_INT_IRQ_PENDING, wdt_pending, NULL);
	avr_irq_register_notify(wdt->watchdog.irq + AVR_INT_IRQ_RUNNING, wdt_running, NULL);
	wdt_ioctl = wdt->io.ioctl;
	wdt->io.ioctl = wdt_ioctl_wdr;
}

void mcu_on_reset(void)
{
	wdt_unserved = 0;
	wdt_reset_due = 0;
}

void mcu_watchdog_after_reset(avr_t *avr, uint8_t mcusr)
{
	if (!wdt || !(mcusr & 0x08) || avr_regbit_get(avr, wdt->wde))
		return;
	/* WDE forced on, WDP at its reset value: the timed sequence (WDCE with WDE, then WDE) through simavr's
	 * own register handler, so that its timer runs as after its own watchdog reset */
	uint16_t a = wdt->wde.reg;
	avr_io_write_t w = avr->io[AVR_DATA_TO_IO(a)].w.c;
	void *p = avr->io[AVR_DATA_TO_IO(a)].w.param;
	uint8_t wdce = (uint8_t)(1 << wdt->wdce.bit), wde = (uint8_t)(1 << wdt->wde.bit);
	if (!w)
		return;
	w(avr, a, (uint8_t)(wdce | wde), p);
	w(avr, a, wde, p);
}

int mcu_watchdog_poll(avr_t *avr)
{
	if (!wdt_reset_due)
		return 0;
	wdt_reset_due = 0;
	/* the vector may have run meanwhile, or the program switched the watchdog off */
	return wdt_unserved && avr_regbit_get(avr, wdt->wde);
}

void mcu_watchdog_forget_pending(avr_t *avr)
{
	if (wdt && wdt->reset_context.wdrf) {
		wdt->reset_context.wdrf = 0;
		avr->run = wdt->reset_context.avr_run;
	}
}

void mcu_watchdog_reset(avr_t *avr)
{
	if (wdt) {
		wdt->reset_context.wdrf = 1;
		wdt->reset_context.avr_run = avr->run;
	}
}

/* ---------------------------------------------------------------- a program that restarts itself
 * A program may leave an interrupt handler by a jump to its reset vector instead of RETI (the sphere's firmware
 * restarts itself so from its watchdog interrupt). The chip keeps no record of running handlers (only SREG's I
 * bit, which the handler's entry cleared); simavr keeps a stack of them, 64 deep, that only RETI pops. At the
 * reset vector with that stack not empty, the board empties it, so a program that restarts itself a hundred
 * times runs on as on the chip. */
void mcu_at_reset_vector(avr_t *avr)
{
	while (avr->interrupts.running_ptr) {
		avr_int_vector_t *v = avr->interrupts.running[--avr->interrupts.running_ptr];
		if (v)
			avr_raise_irq(v->irq + AVR_INT_IRQ_RUNNING, 0);
	}
}

/* ---------------------------------------------------------------- a hung main program */
static avr_run_t hang_run;

int mcu_hang_begin(avr_t *avr)
{
	if (!avr->sreg[S_I] || avr->interrupts.running_ptr)
		return 0; /* a hang in the main program with interrupts enabled: wait for such a moment */
	hang_run = avr->run;
	return 1;
}

void mcu_hang_step(avr_t *avr)
{
	if (avr->interrupts.running_ptr || avr->run != hang_run) {
		avr_run(avr); /* an interrupt handler runs as usual; a reset (the watchdog's) goes through */
		return;
	}
	avr_cycle_count_t next = avr_cycle_timer_process(avr);
	if (avr->run != hang_run) /* the watchdog's reset, due now */
		return;
	avr->cycle += next > 0 && next < 64 ? next : (next ? 64 : 1);
	avr_service_interrupts(avr);
}

/* ---------------------------------------------------------------- the bus's pins and levels
 * SDA and SCL are PC4 and PC5. With the TWI on, it drives them low or lets go, and "the internal pull-ups in
 * the AVR pads can be enabled by setting the PORT bits corresponding to the SCL and SDA pins" ("TWI – Overview
 * of the TWI Module", "SCL and SDA Pins"); with it off, the port drives them. The sensor boards pull the lines up
 * to their 3.3 V; the ATmega's pull-up (R_PU 20–50 kΩ, "DC Characteristics") goes to its 5 V. Idle high level
 * with both: V = (5/R_PU + 3.3/R_ext) / (1/R_PU + 1/R_ext), highest at R_PU = 20 kΩ. The sensors' limit: the
 * ADXL345's absolute maximum on a digital pin, VDD I/O + 0.3 V = 3.6 V at the boards' 3.3 V. A pin driven high
 * (output, port bit 1, TWI off) puts 5 V on the line. The TWI's SCL low time: half the period less two CPU
 * cycles ("2-wire Serial Interface Characteristics", its notes), the period 16 + 2·TWBR·4^TWPS cycles. */
enum { PINC_ = 0x26, DDRC_ = 0x27, PORTC_ = 0x28, TWBR_ = 0xB8, TWSR_ = 0xB9, TWCR_ = 0xBC };
enum { SDA_BIT = 1 << 4, SCL_BIT = 1 << 5, TWEN_BIT = 1 << 2 };
static double bus_r_ext_kohm = 4.7;
mcu_bus_t mcu_bus = {.scl_low_us_min = 1e9, .limit_v = 3.6};

static void bus_check(avr_t *avr, uint8_t ddr, uint8_t port, uint8_t twcr)
{
	int twi = (twcr & TWEN_BIT) != 0;
	uint8_t pulled = (uint8_t)(port & (twi ? (SDA_BIT | SCL_BIT) : (uint8_t)~ddr) & (SDA_BIT | SCL_BIT));
	uint8_t driven = (uint8_t)(twi ? 0 : (ddr & port & (SDA_BIT | SCL_BIT)));
	double t = (double)avr->cycle / avr->frequency;
	if (pulled) {
		double rpu = 20.0, rx = bus_r_ext_kohm;
		double v = (5.0 / rpu + 3.3 / rx) / (1.0 / rpu + 1.0 / rx);
		if (!mcu_bus.pullup_events++)
			mcu_bus.first_pullup_s = t;
		if (v > mcu_bus.idle_high_v_max)
			mcu_bus.idle_high_v_max = v;
	}
	if (driven) {
		if (!mcu_bus.driven_high_events++)
			mcu_bus.first_driven_high_s = t;
		mcu_bus.idle_high_v_max = 5.0;
	}
}

static void bus_port_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
	(void)param;
	uint8_t ddr = addr == DDRC_ ? v : avr->data[DDRC_];
	uint8_t port = addr == PORTC_ ? v : avr->data[PORTC_];
	uint8_t twcr = addr == TWCR_ ? v : avr->data[TWCR_];
	bus_check(avr, ddr, port, twcr);
	if (addr == TWCR_ && (v & TWEN_BIT)) {
		uint32_t twbr = avr->data[TWBR_], twps = avr->data[TWSR_] & 3u;
		double period = 16.0 + 2.0 * twbr * (double)(1u << (2 * twps));
		double low_us = (period / 2 - 2) / (avr->frequency / 1e6);
		if (low_us < mcu_bus.scl_low_us_min) {
			mcu_bus.scl_low_us_min = low_us;
			mcu_bus.scl_khz = avr->frequency / period / 1e3;
		}
	}
}

void mcu_bus_init(avr_t *avr, double r_ext_kohm)
{
	bus_r_ext_kohm = r_ext_kohm;
	/* after the port's and the TWI's own handlers (simavr shares a register between handlers in order) */
	avr_register_io_write(avr, DDRC_, bus_port_write, NULL);
	avr_register_io_write(avr, PORTC_, bus_port_write, NULL);
	avr_register_io_write(avr, TWCR_, bus_port_write, NULL);
}
