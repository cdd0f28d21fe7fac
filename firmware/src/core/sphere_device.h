// The device's behaviour, hardware-free: sensors → calibration → MARG filter → events → frames, and
// host commands → replies. src/main.cpp feeds it timer ticks and received bytes; everything it needs
// from the board goes through DeviceHal and I2cBus, so the native tests run it against fakes.
#pragma once
#include <stdint.h>

#include "adxl345.h"
#include "calibration.h"
#include "command_parser.h"
#include "framing.h"
#include "gyro_bias.h"
#include "hmc5883l.h"
#include "i2c_bus.h"
#include "itg3200.h"
#include "marg_filter.h"
#include "packets.h"
#include "tap_guard.h"

namespace sphere {

class DeviceHal {
public:
    virtual uint32_t micros() = 0;
    // Queues a whole frame for the UART, or nothing (false) when the transmit buffer lacks room.
    virtual bool send(const uint8_t* frame, uint8_t len) = 0;
    virtual void eepromRead(uint8_t* out, uint8_t len) = 0;
    virtual bool eepromWrite(const uint8_t* data, uint8_t len) = 0;
    // Timing pin (D13): high exactly while the MARG update runs.
    virtual void margPin(bool high) = 0;
    // True when the ADXL345's INT1 fired (edge captured or line high); t_us = when it was seen.
    virtual bool adxlInterrupt(uint32_t& t_us) = 0;
    virtual void identify(uint8_t seconds) = 0;
    // Called after the REBOOT reply was queued: flush it, then let the watchdog reset the chip.
    virtual void reboot() = 0;
    virtual uint16_t i2cRecoveries() = 0;
    virtual uint16_t batteryMv() = 0;

protected:
    ~DeviceHal() {}
};

class SphereDevice {
public:
    static const uint16_t STARTUP_CONVERGE_SAMPLES = 400;  // start-up gain for 2 s of accepted accelerometer
    static const uint16_t STARTUP_BIAS_SAMPLES = 200;    // 1 s still at power-up
    static const uint16_t STARTUP_BIAS_TRIES = 10;       // give up after 10 windows with motion
    static const uint16_t STEP_BIAS_SAMPLES = 400;       // 2 s for CALIBRATION_STEP gyro_bias
    static const uint8_t RETRY_TICKS = 200;              // look for a missing sensor once a second
    static const uint32_t FREE_FALL_GAP_US = 250000;     // FREE_FALL quiet this long ends a fall

    SphereDevice(I2cBus& bus, DeviceHal& hal);

    // Probes the sensors, loads the calibration, sends a 0x00 and HELLO.
    void begin();
    // One period of the 200 Hz sample clock.
    void tick();
    // One byte from the host.
    void receive(uint8_t byte);
    // Sample periods whose work ran past the next tick (counted by the timer adapter).
    void noteOverruns(uint16_t n) { status_.loop_overruns = (uint16_t)(status_.loop_overruns + n); }

    // Read-only views for tests and the adapter.
    const Status& status() const { return status_; }
    uint8_t sensorsFound() const { return sensors_found_; }
    uint8_t sensorsOk() const { return sensors_ok_; }
    uint8_t streamMode() const { return stream_mode_; }
    uint8_t calibrationState() const { return cal_state_; }
    const Calibration& calibration() const { return cal_; }
    const MargFilter& filter() const { return filter_; }
    bool tapActive() const { return tap_active_; }

private:
    void probe(uint8_t sensor);
    void readSensors(uint32_t t_us);
    void handleEvents();
    void runFilter();
    void stream(uint32_t t_us);
    void execute(const uint8_t* payload, uint8_t len);
    uint8_t executeCommand(const Command& c);
    void sendPacket(uint8_t type, const uint8_t* body, uint8_t len);
    void sendHello();
    void sendStatus();
    void loadCalibration(bool at_start);
    void updateCalState();
    void i2cError(uint8_t sensor_index);
    void endBiasEstimate();

    I2cBus& bus_;
    DeviceHal& hal_;
    Adxl345 adxl_;
    Itg3200 itg_;
    Hmc5883l hmc_;
    MargFilter filter_;
    TapGuard guard_;
    GyroBiasEstimator bias_est_;
    Calibration cal_;
    FrameEncoder encoder_;
    FrameDecoder decoder_;
    TapSettings tap_;
    FreeFallSettings ff_;
    // status_ and the members after it are zeroed together by the constructor; keep last_fall_us_ last
    Status status_;

    int16_t raw_accel_[3], raw_gyro_[3], raw_mag_[3];
    uint32_t sample_t_us_;
    uint16_t converge_left_;   // accepted samples still to run at the start-up gain
    uint8_t phase_;            // 0 … 199 within the second
    uint8_t retry_;
    uint8_t sensors_found_, sensors_ok_;
    uint8_t raw_flags_, ori_flags_;
    bool mag_seen_, mag_fresh_since_raw_, tap_active_;
    uint8_t stream_mode_;
    uint16_t raw_rate_hz_, orientation_rate_hz_;
    uint16_t beta_milli_;
    uint8_t cal_state_;
    uint8_t cal_step_;
    bool bias_at_startup_;
    uint8_t bias_tries_;
    uint16_t max_work_us_;
    bool falling_;
    uint32_t last_fall_us_;
};

}  // namespace sphere
