// Register-map fakes of the three chips on one I²C bus, and a fake board for SphereDevice.
#pragma once
#include <cstring>
#include <vector>

#include "framing.h"
#include "sphere_device.h"

// One framed packet as the host would send it (type, seq, body).
inline std::vector<uint8_t> frameOf(uint8_t type, uint8_t seq, std::vector<uint8_t> body) {
    uint8_t out[sphere::MAX_FRAME];
    size_t n = sphere::FrameEncoder::encodeWithSeq(type, seq, body.data(), (uint8_t)body.size(), out);
    return std::vector<uint8_t>(out, out + n);
}

struct FakeChip {
    uint8_t addr = 0;
    bool present = true;
    uint8_t regs[128] = {};
    std::vector<std::pair<uint8_t, uint8_t>> writes;  // (reg, value)
};

struct FakeBus : sphere::I2cBus {
    FakeChip adxl, itg, hmc, qmc;
    int transactions = 0;
    FakeBus() {
        qmc.addr = 0x0D;  // QMC5883L: absent unless a test fits one instead of the HMC5883L
        qmc.present = false;
        qmc.regs[0x0D] = 0xFF;
        adxl.addr = 0x53;
        adxl.regs[0x00] = 0xE5;
        itg.addr = 0x68;
        itg.regs[0x00] = 0x69;  // WHO_AM_I as shipped (AD0 bit reads back as 1 on many boards)
        hmc.addr = 0x1E;
        hmc.regs[0x0A] = 'H';
        hmc.regs[0x0B] = '4';
        hmc.regs[0x0C] = '3';
    }
    FakeChip* chip(uint8_t a) {
        for (FakeChip* c : {&adxl, &itg, &hmc, &qmc})
            if (c->addr == a && c->present) return c;
        return nullptr;
    }
    bool writeRegisters(uint8_t addr, uint8_t reg, const uint8_t* d, uint8_t n) override {
        ++transactions;
        FakeChip* c = chip(addr);
        if (!c) return false;
        for (uint8_t i = 0; i < n; ++i) {
            c->regs[(reg + i) & 127] = d[i];
            c->writes.push_back({(uint8_t)(reg + i), d[i]});
        }
        // HMC5883L single measurement: RDY stays set after a data read and clears when the chip starts
        // writing the next conversion (datasheet, status register); setMag() is that conversion's end
        if (c == &hmc && reg == 0x02 && n == 1 && d[0] == 0x01) hmc.regs[0x09] &= ~1;
        return true;
    }
    bool readRegisters(uint8_t addr, uint8_t reg, uint8_t* out, uint8_t n) override {
        ++transactions;
        FakeChip* c = chip(addr);
        if (!c) return false;
        for (uint8_t i = 0; i < n; ++i) out[i] = c->regs[(reg + i) & 127];
        if (c == &adxl && reg == 0x30) adxl.regs[0x30] &= 0x83;  // INT_SOURCE read clears the events
        if (c == &qmc && reg <= 0x05) qmc.regs[0x06] &= ~1;      // QMC5883L: reading data clears DRDY
        return true;
    }
    // sensor values in chip units, written into the registers as each chip lays them out
    void setAccel(int16_t x, int16_t y, int16_t z) {
        int16_t v[3] = {x, y, z};
        for (int i = 0; i < 3; ++i) {
            adxl.regs[0x32 + 2 * i] = (uint8_t)v[i];
            adxl.regs[0x33 + 2 * i] = (uint8_t)((uint16_t)v[i] >> 8);
        }
    }
    void setGyro(int16_t x, int16_t y, int16_t z) {
        int16_t v[3] = {x, y, z};
        for (int i = 0; i < 3; ++i) {
            itg.regs[0x1D + 2 * i] = (uint8_t)((uint16_t)v[i] >> 8);
            itg.regs[0x1E + 2 * i] = (uint8_t)v[i];
        }
    }
    void setMag(int16_t x, int16_t y, int16_t z) {
        int16_t v[3] = {x, z, y};  // the chip's order: X, Z, Y
        for (int i = 0; i < 3; ++i) {
            hmc.regs[0x03 + 2 * i] = (uint8_t)((uint16_t)v[i] >> 8);
            hmc.regs[0x04 + 2 * i] = (uint8_t)v[i];
        }
        hmc.regs[0x09] |= 1;
    }
    // QMC5883L: little-endian X, Y, Z (3000 LSB/G at ±8 G), DRDY set; `overflow` sets OVL
    void setQmc(int16_t x, int16_t y, int16_t z, bool overflow = false) {
        int16_t v[3] = {x, y, z};
        for (int i = 0; i < 3; ++i) {
            qmc.regs[2 * i] = (uint8_t)v[i];
            qmc.regs[2 * i + 1] = (uint8_t)((uint16_t)v[i] >> 8);
        }
        qmc.regs[0x06] = (uint8_t)(1 | (overflow ? 2 : 0));
    }
};

struct FakeHal : sphere::DeviceHal {
    uint32_t now = 0;
    std::vector<uint8_t> wire;
    uint8_t eeprom[1024];
    bool eeprom_fails = false;
    int pin_high = 0, pin_pulses = 0;
    bool interrupt = false;
    uint32_t interrupt_t = 0;
    int identify_s = 0, reboots = 0;
    bool tx_full = false;
    int tx_room = 255;  // free transmit-buffer bytes txRoom() reports
    uint8_t reset_cause = sphere::RESET_POWER_ON;
    FakeHal() { std::memset(eeprom, 0xFF, sizeof eeprom); }
    uint8_t txRoom() override { return tx_full ? 0 : (uint8_t)tx_room; }
    uint8_t resetCause() override { return reset_cause; }
    sphere::KeptBias kept{};  // the RAM a reset other than a power-on keeps: a new SphereDevice on this hal sees it
    sphere::KeptBias& keptBias() override { return kept; }
    uint32_t micros() override { return now += 4; }
    bool send(const uint8_t* f, uint8_t n) override {
        if (tx_full) return false;
        wire.insert(wire.end(), f, f + n);
        return true;
    }
    void eepromRead(uint16_t a, uint8_t* out, uint8_t n) override { std::memcpy(out, eeprom + a, n); }
    // eeprom_write_us = 0: every write is done at once; else the ATmega328P's EEPE: busy that long after a byte
    uint32_t eeprom_write_us = 0, eeprom_busy_until = 0;
    int eeprom_bytes_written = 0;
    bool eepromReady() override { return !eeprom_write_us || (int32_t)(now - eeprom_busy_until) >= 0; }
    bool eepromWriteByte(uint16_t a, uint8_t v) override {
        if (eeprom_fails || !eepromReady()) return false;
        eeprom[a] = v;
        ++eeprom_bytes_written;
        eeprom_busy_until = now + eeprom_write_us;
        return true;
    }
    std::vector<size_t> wire_at_pin;  // the wire's length each time the timing pin rose (the MARG update began)
    void margPin(bool h) override {
        if (h) {
            ++pin_pulses;
            wire_at_pin.push_back(wire.size());
        }
        pin_high = h;
    }
    bool adxlInterrupt(uint32_t& t) override {
        if (!interrupt) return false;
        interrupt = false;
        t = interrupt_t;
        return true;
    }
    void identify(uint8_t s) override { identify_s = s; }
    void reboot() override { ++reboots; }
    uint32_t baud = 115200;
    int baud_switches = 0;
    void setBaud(uint32_t b) override {
        baud = b;
        ++baud_switches;
    }
    uint16_t i2cRecoveries() override { return 0; }
    uint16_t batteryMv() override { return 0; }

    // frames sent since the last call, as CRC-good payloads
    std::vector<std::vector<uint8_t>> frames() {
        std::vector<std::vector<uint8_t>> out;
        sphere::FrameDecoder d;
        for (uint8_t b : wire)
            if (d.push(b) == sphere::FRAME_OK) out.emplace_back(d.payload(), d.payload() + d.payloadLength());
        wire.clear();
        return out;
    }
};
