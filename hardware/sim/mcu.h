/* The ATmega328P itself where the board adds to simavr 1.6 or corrects it to the datasheet: the boot loader
 * in front of the program, the EEPROM's write time, the watchdog after a reset and in its interrupt and
 * system reset mode, and a program that hangs. SPDX-License-Identifier: GPL-3.0-or-later (links simavr). */
#ifndef SPHERE_MCU_H
#define SPHERE_MCU_H

#include <stddef.h>
#include <stdint.h>
#include "sim_avr.h"

/* Loads an Intel HEX boot loader into the flash and moves the reset vector to its first address (the Nano's
 * fuses: BOOTRST programmed, BOOTSZ the boot section that starts there). Fails (message in err) when the
 * file cannot be read, lies outside the flash, or overlaps the program already loaded (app_bytes). */
int mcu_load_bootloader(avr_t *avr, const char *path, uint32_t app_bytes, uint32_t *start, uint32_t *size,
			char *err, size_t errlen);

/* MCUSR's flags cleared by writing zero, never set by writing one (simavr 1.6 stores what is written). */
void mcu_mcusr_flags(avr_t *avr, uint16_t mcusr_addr);

/* The EEPROM's write time (EECR's EEPE stays set until the cell is written) in place of simavr's at once. */
void mcu_eeprom_timing(avr_t *avr);
extern uint32_t mcu_eeprom_writes;        /* bytes written (erase+write, erase or write operations) */

/* The watchdog as the datasheet has it where simavr 1.6 differs (mcu.c says where); call once after
 * avr_init, mcu_watchdog_after_reset(avr, mcusr) after every reset with the MCUSR the program will find,
 * and mcu_watchdog_poll(avr) from the main loop: it returns 1 when the watchdog resets the MCU now (the
 * board then resets it with WDRF, mcu_watchdog_reset). */
void mcu_watchdog_init(avr_t *avr);
void mcu_watchdog_after_reset(avr_t *avr, uint8_t mcusr);
void mcu_on_reset(void); /* from the board's reset hook: a reset clears the watchdog's state */
int mcu_watchdog_poll(avr_t *avr);
/* a power-on at the instant simavr's watchdog reset is due: the power-on's (PORF alone) is the one that counts */
void mcu_watchdog_forget_pending(avr_t *avr);
void mcu_watchdog_reset(avr_t *avr); /* arm simavr's own watchdog-reset path, then call avr_reset */
extern uint32_t mcu_watchdog_interrupts;  /* watchdog interrupts raised */

/* Call when the program is at its reset vector (pc 0): an interrupt handler it left by a jump there has ended. */
void mcu_at_reset_vector(avr_t *avr);

/* A hang of the main program (e.g. a loop waiting for a flag that never comes): no instruction outside an
 * interrupt handler runs, while the peripherals, their interrupts and the watchdog go on. mcu_hang_begin
 * takes the stack pointer of the main program (it waits for a moment with interrupts enabled); mcu_hang_step
 * replaces avr_run while the hang lasts. */
int mcu_hang_begin(avr_t *avr);
void mcu_hang_step(avr_t *avr);

/* The I2C pins' levels (mcu.c): whether the AVR's own pull-ups (to 5 V) were on beside the sensor boards'
 * (to 3.3 V through r_ext_kohm), or a line driven high; the highest idle level against the sensors' limit; the
 * SCL low time the TWI's bit rate gives. */
typedef struct {
	uint32_t pullup_events, driven_high_events;
	double first_pullup_s, first_driven_high_s;
	double idle_high_v_max, limit_v;
	double scl_low_us_min, scl_khz;
} mcu_bus_t;
extern mcu_bus_t mcu_bus;
void mcu_bus_init(avr_t *avr, double r_ext_kohm);

#endif
