/* Smoke test of the real firmware image (firmware/build/sphere.elf) on simavr, with no sensors on the
 * bus: it must boot, send 0x00 + HELLO (seq 0, sensors_found 0), keep the 200 Hz loop running
 * (STATUS once a second, RAW_SAMPLE at 200 Hz, ORIENTATION at 100 Hz). Without a gyroscope the orientation
 * is held (ORIENTATION flag gyro_missing) and no MARG update runs, so D13 (PB5) must stay low.
 * Usage: sim_smoke firmware/build/sphere.elf [seconds]     (make -C firmware sim-smoke) */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

static avr_t* avr;
static uint8_t chunk[80];
static int fill, frames, hello, raws, oris, statuses, bad, first_byte = -1, first_type = -1, first_seq = -1;
static int hello_sensors = -1, hello_version = -1, oris_held;
static uint64_t pin_rise, pulses, pulse_cycles, pulse_max;

static uint16_t crc16(const uint8_t* d, int n) {
    uint16_t c = 0xFFFF;
    for (int i = 0; i < n; ++i) {
        c ^= (uint16_t)d[i] << 8;
        for (int b = 0; b < 8; ++b) c = (c & 0x8000) ? (uint16_t)((c << 1) ^ 0x1021) : (uint16_t)(c << 1);
    }
    return c;
}

static void frame_done(void) {
    uint8_t out[80];
    int i = 0, o = 0;
    if (fill == 0) return;
    while (i < fill) {
        int code = chunk[i++];
        for (int k = 1; k < code; ++k) {
            if (i >= fill) { ++bad; return; }
            out[o++] = chunk[i++];
        }
        if (code != 0xFF && i < fill) out[o++] = 0;
    }
    if (o < 4 || crc16(out, o - 2) != (uint16_t)(out[o - 2] | (out[o - 1] << 8))) { ++bad; return; }
    ++frames;
    if (first_type < 0) { first_type = out[0]; first_seq = out[1]; }
    switch (out[0]) {
        case 1: ++hello; hello_version = out[2]; hello_sensors = out[6]; break;
        case 2: ++raws; break;
        case 3: ++oris; oris_held += (out[6] & 0x10) != 0; break;
        case 5: ++statuses; break;
    }
}

static void uart_out(struct avr_irq_t* irq, uint32_t value, void* param) {
    (void)irq; (void)param;
    if (first_byte < 0) first_byte = (int)value;
    if (value == 0) { frame_done(); fill = 0; }
    else if (fill < (int)sizeof chunk) chunk[fill++] = (uint8_t)value;
    else ++bad;
}

static void pin_b5(struct avr_irq_t* irq, uint32_t value, void* param) {
    (void)irq; (void)param;
    if (value) pin_rise = avr->cycle;
    else if (pin_rise) {
        uint64_t w = avr->cycle - pin_rise;
        if (w > 100000) return; /* the power-up blinks, not a MARG update */
        ++pulses;
        pulse_cycles += w;
        if (w > pulse_max) pulse_max = w;
    }
}

int main(int argc, char** argv) {
    if (argc < 2) { fprintf(stderr, "usage: %s sphere.elf [seconds]\n", argv[0]); return 2; }
    double seconds = argc > 2 ? atof(argv[2]) : 2.2;
    elf_firmware_t f;
    memset(&f, 0, sizeof f);
    if (elf_read_firmware(argv[1], &f)) { fprintf(stderr, "cannot read %s\n", argv[1]); return 2; }
    avr = avr_make_mcu_by_name("atmega328p");
    if (!avr) return 2;
    avr_init(avr);
    avr->frequency = 16000000;
    avr_load_firmware(avr, &f);
    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~AVR_UART_FLAG_STDIO;
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 5), pin_b5, NULL);
    uint64_t end = (uint64_t)(seconds * 16e6);
    while (avr->cycle < end) {
        int st = avr_run(avr);
        if (st == cpu_Done || st == cpu_Crashed) { fprintf(stderr, "cpu stopped (%d)\n", st); break; }
    }
    printf("sim: %.1f s simulated; first byte 0x%02x; first frame type %d seq %d; HELLO %d (protocol %d, "
           "sensors_found %d); RAW_SAMPLE %d; ORIENTATION %d; STATUS %d; bad chunks %d\n",
           seconds, first_byte & 0xFF, first_type, first_seq, hello, hello_version, hello_sensors, raws, oris,
           statuses, bad);
    printf("sim: D13 pulses %llu (none expected: no gyroscope, orientation held); ORIENTATION with gyro_missing %d\n",
           (unsigned long long)pulses, oris_held);
    int ok = first_byte == 0 && first_type == 1 && first_seq == 0 && hello == 1 && hello_version == 2 &&
             hello_sensors == 0 && statuses >= 1 && raws > 150 * (seconds - 1) && bad == 0 && pulses == 0 &&
             oris > 75 * (seconds - 1) && oris_held == oris;
    printf("sim: %s\n", ok ? "ok" : "FAILED");
    return ok ? 0 : 1;
}
