// The device's behaviour, hardware-free: sensors → calibration → MARG filter → events → frames, and
// host commands → replies. src/main.cpp feeds it timer ticks and received bytes; everything it needs
// from the board goes through DeviceHal and I2cBus, so the native tests run it against fakes.
#pragma once
#include <stdint.h>

#include "adxl345.h"
#include "board_profile.h"
#include "calibration.h"
#include "command_parser.h"
#include "framing.h"
#include "gyro_bias.h"
#include "hmc5883l.h"
#include "i2c_bus.h"
#include "input_gates.h"
#include "itg3200.h"
#include "kept_bias.h"
#include "marg_filter.h"
#include "packets.h"
#include "qmc5883l.h"
#include "settings_image.h"
#include "tap_guard.h"

namespace sphere {

class DeviceHal {
public:
    virtual uint32_t micros() = 0;
    // Queues a whole frame for the UART, or nothing (false) when the transmit buffer lacks room.
    virtual bool send(const uint8_t* frame, uint8_t len) = 0;
    // Free bytes in the transmit buffer now.
    virtual uint8_t txRoom() = 0;
    virtual void eepromRead(uint16_t addr, uint8_t* out, uint8_t len) = 0;
    // EEPROM writes never wait: eepromReady() is false while a byte is being written (3.4 ms on the ATmega328P,
    // "EEPROM Mode Bits"), and eepromWriteByte() starts writing one byte (false when it cannot). SphereDevice
    // writes a block a byte at a time from tick(), so no sample period waits for the EEPROM.
    virtual bool eepromReady() = 0;
    virtual bool eepromWriteByte(uint16_t addr, uint8_t value) = 0;
    // Why the chip last reset: HELLO reset_cause bits (captured before anything cleared them).
    virtual uint8_t resetCause() = 0;
    // The gyro bias record in RAM that a reset other than a power-on leaves as it was (kept_bias.h).
    virtual KeptBias& keptBias() = 0;
    // Timing pin (D13): high exactly while the MARG update runs.
    virtual void margPin(bool high) = 0;
    // True when the ADXL345's INT1 fired (edge captured or line high); t_us = when it was seen.
    virtual bool adxlInterrupt(uint32_t& t_us) = 0;
    virtual void identify(uint8_t seconds) = 0;
    // Called after the REBOOT reply was queued: flush it, then start the firmware again (AvrBoard: a restart
    // from the reset vector, not a watchdog reset).
    virtual void reboot() = 0;
    // The UART to `baud` once what is queued has left at the old rate (SET_BAUD, spec §5.4).
    virtual void setBaud(uint32_t baud) = 0;
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
    static const uint16_t TRACK_SAMPLES = 200;           // 1 s still windows for bias tracking
    static const int16_t TRACK_STEP_LSB = 2;             // the most one tracking window moves the bias
    // ORIENTATION is the state predicted this far ahead at the current rate: the ITG-3200's delay at
    // DLPF_CFG 2 (2.8 ms: itg3200.h) plus half its 1 ms output period (the mean age of the register when
    // read, SMPLRT_DIV 0), so the quaternion is the orientation at the packet's t_us
    static const uint16_t GYRO_DELAY_US = 3300;
    // a gap of up to this many periods without a fresh gyroscope sample (stale or missing) is bridged
    // by the trapezoid rule when the gyroscope is back (SphereDevice::bridgeGap)
    static const uint8_t GAP_BRIDGE_TICKS = 20;
    static const uint8_t MISSING_AFTER = 10;   // consecutive failed reads (50 ms) before a sensor is missing
    static const uint8_t FAST_PROBES = 200;    // a missing sensor is probed every period this many times,
    static const uint8_t SLOW_PROBE_TICKS = 20;  // then every 20th period (10 Hz)
    static const uint32_t FREE_FALL_GAP_US = 250000;     // FREE_FALL quiet this long ends a fall
    static const uint16_t BOARD_EEPROM_ADDR = 64;        // board profile byte and its complement
    // The longest reply and what follows it (GET_CALIBRATION's 52-byte frame): a command is taken
    // from the receive buffer only when the transmit buffer has this much room, so it is never dropped.
    static const uint8_t REPLY_ROOM = 52;
    // executeCommand's answer for a command whose REPLY is sent later (not a wire value)
    static const uint8_t RESULT_LATER = 0xFF;

    SphereDevice(I2cBus& bus, DeviceHal& hal);

    // Probes the sensors, loads the calibration, sends a 0x00 and HELLO.
    void begin();
    // One period of the 200 Hz sample clock.
    void tick();
    // One byte from the host. False when the byte was not taken: it ends a command whose reply does
    // not fit the transmit buffer yet; offer it again later (it waits in the UART's receive buffer).
    bool receive(uint8_t byte);
    // Sample periods whose work ran past the next tick (counted by the timer adapter).
    void noteOverruns(uint16_t n) { status_.loop_overruns = (uint16_t)(status_.loop_overruns + n); }

    // Read-only views for tests and the adapter.
    const Status& status() const { return status_; }
    uint8_t sensorsFound() const { return sensors_found_; }
    uint8_t sensorsOk() const { return sensors_ok_; }
    uint8_t streamMode() const { return stream_mode_; }
    uint8_t calibrationState() const { return cal_state_; }
    uint8_t settingsState() const { return settings_state_; }
    // The settings in use as the block of protocol/spec.md §5.3 (GET_SETTINGS, SAVE_SETTINGS).
    void settingsBlock(uint8_t out[SETTINGS_BLOCK_LEN]) const;
    uint8_t boardProfile() const { return board_profile_; }
    uint8_t magChip() const { return mag_chip_; }
    uint8_t rawFlags() const { return raw_flags_; }
    uint8_t orientationFlags() const { return ori_flags_; }
    const Calibration& calibration() const { return cal_; }
    const MargFilter& filter() const { return filter_; }
    InputGates& gates() { return gates_; }
    // The quaternion an ORIENTATION packet carries now (the filter's state GYRO_DELAY_US ahead), Q14.
    void orientationQ14(int16_t out[4]) const { filter_.predictQ14(gyro_, GYRO_DELAY_US, out); }
    bool tapActive() const { return tap_active_; }
    // The UART's rate (spec §5.4) and whether the device waits for the host's first frame at it.
    uint32_t baud() const { return baud_ ? baud_ : DEFAULT_BAUD; }
    bool linkQuiet() const { return link_quiet_; }

private:
    bool probe(uint8_t index);
    bool readSensor(uint8_t index, bool& fresh);
    void readSensors(uint8_t first, uint8_t last);
    void trackBias();
    void keepTrackedBias();
    bool magAccepted(const int16_t m[3]);
    void handleEvents();
    void runFilter(uint16_t dt_us);
    void bridgeGap(const int16_t g[3], uint16_t dt_us);
    void streamRaw(uint32_t t_us);
    void stream(uint32_t t_us);
    void execute(const uint8_t* payload, uint8_t len);
    uint8_t executeCommand(const Command& c);
    void sendPacket(uint8_t type, const uint8_t* body, uint8_t len);
    void switchBaud(uint32_t baud);
    void watchLink();
    void sendHello();
    void sendStatus();
    void loadCalibration(bool at_start);
    void updateCalState();
    void endBiasEstimate();
    void loadBoardProfile();
    void loadSettings();
    bool applySettings(const uint8_t block[SETTINGS_BLOCK_LEN]);
    uint8_t startStore(const Command& c, uint16_t addr, const uint8_t* data, uint8_t len);
    void serviceStore();
    void finishStore(uint8_t result);

    I2cBus& bus_;
    DeviceHal& hal_;
    Adxl345 adxl_;
    Itg3200 itg_;
    Hmc5883l hmc_;
    Qmc5883l qmc_;
    MargFilter filter_;
    TapGuard guard_;
    GyroBiasEstimator bias_est_;
    InputGates gates_;
    Calibration cal_;
    FrameEncoder encoder_;
    FrameDecoder decoder_;
    TapSettings tap_;
    FreeFallSettings ff_;
    // status_ and the members after it are zeroed together by the constructor; keep last_fall_us_ last
    Status status_;

    int16_t raw_[3][3];        // accelerometer, gyroscope, magnetometer: body frame, last good read
    int16_t gyro_[3];          // the calibrated rate of the last update (0 while the gyro is missing)
    int16_t g_fresh_[3];       // the calibrated rate of the last fresh gyroscope sample
    uint8_t gap_, gap_held_;   // periods since it without a fresh sample; of those, with the held one integrated
    uint32_t sample_t_us_, last_t_us_;
    uint16_t converge_left_;   // accepted samples still to run at the start-up gain
    uint8_t phase_;            // 0 … 199 within the second
    uint8_t fails_[3];         // consecutive failed reads (present) or failed probes (missing)
    uint8_t sensors_found_, sensors_ok_;
    uint8_t mag_chip_, board_profile_, reset_cause_;
    bool tracking_;            // the bias estimator runs a still-window for bias tracking
    uint8_t raw_flags_, ori_flags_;
    bool mag_seen_, mag_fresh_since_raw_, tap_active_, mag_overflow_;
    uint8_t stream_mode_;
    uint16_t raw_rate_hz_, orientation_rate_hz_;
    uint16_t beta_milli_;
    uint8_t cal_state_;
    uint8_t settings_state_;
    uint8_t cal_step_;
    bool bias_at_startup_;
    uint8_t bias_tries_;
    uint16_t max_work_us_;
    bool falling_;
    uint32_t baud_;            // SET_BAUD's rate; 0: DEFAULT_BAUD
    uint32_t rx_t_us_;         // when the last intact frame from the host was complete (ECHO's reply)
    uint16_t rx_idle_ticks_;   // periods since then (the fall-back of spec §5.4)
    bool link_quiet_;          // switched: nothing is sent until the host's first intact frame
    // A block on its way into the EEPROM (SAVE_CALIBRATION, SET_BOARD, SAVE_SETTINGS,
    // CLEAR_SETTINGS): a byte whenever the EEPROM is ready,
    // from tick(); the command's REPLY goes when every byte reads back as written. store_cmd_ 0: none.
    uint8_t store_cmd_, store_seq_, store_len_, store_pos_;
    uint16_t store_addr_;
    uint8_t store_buf_[CALIBRATION_EEPROM_LEN > SETTINGS_EEPROM_LEN ? CALIBRATION_EEPROM_LEN : SETTINGS_EEPROM_LEN];
    uint32_t last_fall_us_;
};

}  // namespace sphere
