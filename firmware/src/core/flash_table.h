// Constant tables kept in flash on the AVR (PROGMEM, read with LPM) and in ordinary memory on the
// native build, so the same code reads them on both.
#pragma once
#include <stdint.h>

#ifdef __AVR__
#include <avr/pgmspace.h>
#define SPHERE_TABLE PROGMEM
#define SPHERE_READ_U8(p) pgm_read_byte(p)
#define SPHERE_READ_U16(p) pgm_read_word(p)
#else
#define SPHERE_TABLE
#define SPHERE_READ_U8(p) (*(p))
#define SPHERE_READ_U16(p) (*(p))
#endif
