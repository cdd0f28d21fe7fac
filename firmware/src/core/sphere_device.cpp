#include "sphere_device.h"

#include "bytes.h"

#include <string.h>

#include "bytes.h"

namespace sphere {

// The periodic and command functions below are marked noinline. With link-time optimisation avr-gcc
// otherwise inlines all of them into main(), whose stack frame then grows past what the AVR's 6-bit
// displacement reaches, and every access to a local costs a pointer adjustment: about 900 bytes of
// flash (firmware/MARG_FILTER.md, "Flash and RAM").

SphereDevice::SphereDevice(I2cBus& bus, DeviceHal& hal)
    : bus_(bus), hal_(hal), adxl_(bus), itg_(bus), hmc_(bus), qmc_(bus), filter_(MargFilter::DEFAULT_DT_US) {
    cal_.setDefaults();
    tap_ = Adxl345::DEFAULT_TAP;
    ff_ = Adxl345::DEFAULT_FREE_FALL;
    // status_ and every member after it start at zero: one memset instead of a store per member
    // (198 bytes of flash less); sphere_device.h keeps them together at the end of the class
    memset(&status_, 0, (size_t)((uint8_t*)(&last_fall_us_ + 1) - (uint8_t*)&status_));
    converge_left_ = STARTUP_CONVERGE_SAMPLES;
    stream_mode_ = STREAM_RAW | STREAM_ORIENTATION | STREAM_STATUS;
    raw_rate_hz_ = 200;
    orientation_rate_hz_ = 100;
    beta_milli_ = MargFilter::DEFAULT_BETA_MILLI;
}

// Probes sensor `i` (0 ADXL345, 1 ITG-3200, 2 magnetometer: HMC5883L, else QMC5883L) and configures it.
bool SphereDevice::probe(uint8_t i) {
    bool ok;
    if (i == 0) {
        ok = adxl_.begin(tap_, ff_);
    } else if (i == 1) {
        ok = itg_.begin();
    } else {
        mag_chip_ = MAG_CHIP_HMC5883L;
        ok = hmc_.begin();
        if (!ok) {
            mag_chip_ = MAG_CHIP_QMC5883L;
            ok = qmc_.begin();
        }
        if (!ok) mag_chip_ = MAG_CHIP_NONE;
        mag_seen_ = false;
    }
    uint8_t bit = (uint8_t)(1u << i);
    if (ok) sensors_ok_ |= bit;
    else sensors_ok_ &= (uint8_t)~bit;
    return ok;
}

__attribute__((noinline)) void SphereDevice::begin() {
    reset_cause_ = hal_.resetCause();
    loadBoardProfile();
    loadSettings();  // before the probes: they write the tap and free-fall settings into the ADXL345
    for (uint8_t i = 0; i < 3; ++i) probe(i);
    sensors_found_ = sensors_ok_;
    guard_.setThreshold(tap_.thresh_tap);
    loadCalibration(true);
    filter_.begin(MargFilter::DEFAULT_DT_US);
    filter_.setBetaMilli(MargFilter::STARTUP_BETA_MILLI);
    // After a reset that was not a power-on, the bias tracked before it (kept_bias.h): tracking goes on from
    // it (a still window moves it by TRACK_STEP_LSB at most) and no power-up estimate replaces it.
    KeptBias& k = hal_.keptBias();
    if (!(reset_cause_ & RESET_POWER_ON) && keptBiasValid(k) && (k.cal_bits & CAL_GYRO_BIAS_VALID)) {
        bool changed = false;
        for (uint8_t i = 0; i < 3; ++i) {
            if (k.gyro_bias[i] != cal_.gyro_bias[i]) changed = true;
            cal_.gyro_bias[i] = k.gyro_bias[i];
        }
        if (changed)  // not the EEPROM's bias: as after a tracking window
            cal_state_ = (uint8_t)((cal_state_ & ~(CAL_FROM_EEPROM | CAL_GYRO_BIAS_ESTIMATED)) |
                                   (k.cal_bits & (CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED)));
    } else if (sensors_ok_ & SENSOR_ITG3200) {
        bias_est_.start(STARTUP_BIAS_SAMPLES);
        bias_at_startup_ = true;
        bias_tries_ = 1;
    }
    k.cal_bits = 0xFF;  // no state has these bits: the record is written now, whatever the RAM held
    keepTrackedBias();
    uint8_t zero = 0;
    hal_.send(&zero, 1);  // ends any partial frame in the receiver's buffer
    sendHello();
}

void SphereDevice::loadBoardProfile() {
    uint8_t b[2];
    hal_.eepromRead(BOARD_EEPROM_ADDR, b, 2);
    board_profile_ = (b[0] < BOARD_PROFILE_COUNT && b[1] == (uint8_t)~b[0]) ? b[0] : SPHERE_DEFAULT_BOARD;
}

// The saved settings (spec §5.3), checked by the commands' own parser; a block that fails any check is not
// used at all (the firmware defaults stay) and GET_SETTINGS says so.
void SphereDevice::loadSettings() {
    uint8_t image[SETTINGS_EEPROM_LEN], block[SETTINGS_BLOCK_LEN];
    hal_.eepromRead(SETTINGS_EEPROM_ADDR, image, SETTINGS_EEPROM_LEN);
    SettingsImage r = readSettingsImage(image, block);
    if (r == SETTINGS_IMAGE_VALID && applySettings(block))
        settings_state_ = SETTINGS_SAVED;
    else
        settings_state_ = r == SETTINGS_IMAGE_BLANK ? SETTINGS_NONE_SAVED : SETTINGS_EEPROM_INVALID | SETTINGS_NONE_SAVED;
}

// Every group of the block through CommandParser first; only when all pass are they taken (the chips get
// them from probe()).
bool SphereDevice::applySettings(const uint8_t block[SETTINGS_BLOCK_LEN]) {
    Command c;
    for (uint8_t pass = 0; pass < 2; ++pass) {
        const uint8_t* b = block;
        for (uint8_t g = 0; g < SETTINGS_GROUPS; ++g) {
            uint8_t payload[2 + 5 + 2] = {SETTINGS_GROUP_TYPE[g], 0};
            uint8_t n = SETTINGS_GROUP_LEN[g];
            for (uint8_t i = 0; i < n; ++i) payload[2 + i] = b[i];
            b += n;
            if (CommandParser::parse(payload, (uint8_t)(n + 4), c) != RESULT_OK) return false;
            if (pass == 0) continue;
            if (g == 0) {
                stream_mode_ = c.set_stream.stream_mode;
                raw_rate_hz_ = c.set_stream.raw_rate_hz;
                orientation_rate_hz_ = c.set_stream.orientation_rate_hz;
            } else if (g == 1) {
                tap_ = {c.set_tap.thresh_tap, c.set_tap.dur, c.set_tap.latent, c.set_tap.window, c.set_tap.tap_axes};
            } else if (g == 2) {
                ff_ = {c.set_free_fall.thresh_ff, c.set_free_fall.time_ff};
            } else {
                beta_milli_ = c.set_filter.beta;
            }
        }
    }
    return true;
}

void SphereDevice::settingsBlock(uint8_t out[SETTINGS_BLOCK_LEN]) const {
    out[0] = stream_mode_;
    putU16(out + 1, raw_rate_hz_);
    putU16(out + 3, orientation_rate_hz_);
    out[5] = tap_.thresh_tap;
    out[6] = tap_.dur;
    out[7] = tap_.latent;
    out[8] = tap_.window;
    out[9] = tap_.tap_axes;
    out[10] = ff_.thresh_ff;
    out[11] = ff_.time_ff;
    putU16(out + 12, beta_milli_);
}

void SphereDevice::loadCalibration(bool at_start) {
    uint8_t image[CALIBRATION_EEPROM_LEN];
    hal_.eepromRead(0, image, CALIBRATION_EEPROM_LEN);
    Calibration c;
    if (readCalibrationImage(image, c)) {
        cal_ = c;
        cal_state_ = (uint8_t)((cal_state_ & ~(CAL_EEPROM_INVALID | CAL_GYRO_BIAS_ESTIMATED)) | CAL_FROM_EEPROM |
                               CAL_GYRO_BIAS_VALID);
    } else if (at_start) {
        cal_.setDefaults();
        cal_state_ = (uint8_t)((cal_state_ & ~(CAL_FROM_EEPROM | CAL_GYRO_BIAS_VALID)) | CAL_EEPROM_INVALID);
    }
    updateCalState();
}

void SphereDevice::updateCalState() {
    cal_state_ &= (uint8_t)~(CAL_ACCEL_CALIBRATED | CAL_MAG_CALIBRATED);
    if (!cal_.accelIsDefault()) cal_state_ |= CAL_ACCEL_CALIBRATED;
    if (!cal_.magIsDefault()) cal_state_ |= CAL_MAG_CALIBRATED;
}

// One read of sensor i into raw_[i] (body frame). False on a bus failure (raw_[i] unchanged).
bool SphereDevice::readSensor(uint8_t i, bool& fresh) {
    int16_t v[3];
    bool ok;
    fresh = true;
    if (i == 0) ok = adxl_.readAccel(v);
    else if (i == 1) ok = itg_.readGyro(v);
    else {
        v[0] = v[1] = v[2] = 0;
        ok = mag_chip_ == MAG_CHIP_QMC5883L ? qmc_.poll(v, fresh) : hmc_.poll(v, fresh);
    }
    if (ok && fresh) {
        if (i == 2) mag_overflow_ = v[0] == Hmc5883l::OVERFLOW || v[1] == Hmc5883l::OVERFLOW ||
                                    v[2] == Hmc5883l::OVERFLOW;  // on the chip's reading, before anything else
        mapAxes(board_profile_, i, v);
        for (uint8_t k = 0; k < 3; ++k) raw_[i][k] = v[k];
    }
    return ok;
}

// Reads sensors first … last-1 (0 ADXL345, 1 ITG-3200, 2 magnetometer); their RAW_SAMPLE bits are replaced,
// the others' kept. A failed transaction holds the sensor's last sample (flagged stale); MISSING_AFTER
// failures in a row declare it missing, and a missing sensor is probed again from the next period on.
__attribute__((noinline)) void SphereDevice::readSensors(uint8_t first, uint8_t last) {
    for (uint8_t i = first; i < last; ++i) raw_flags_ &= (uint8_t)~((1u << i) | (RAW_ACCEL_STALE << i));
    for (uint8_t i = first; i < last; ++i) {
        uint8_t bit = (uint8_t)(1u << i);
        if (!(sensors_ok_ & bit)) {
            if (fails_[i] < FAST_PROBES || phase_ % SLOW_PROBE_TICKS == 0) {
                if (probe(i)) {
                    fails_[i] = 0;
                } else {
                    ++status_.probe_failures;
                    if (fails_[i] < 255) ++fails_[i];
                }
            }
            continue;  // read from the next period on
        }
        bool fresh;
        if (readSensor(i, fresh)) {
            fails_[i] = 0;
            if (i == 2 && fresh) {
                mag_seen_ = true;
                mag_fresh_since_raw_ = true;
            }
        } else {
            ++status_.i2c_errors[i];
            if (++fails_[i] >= MISSING_AFTER) {
                sensors_ok_ &= (uint8_t)~bit;
                ++status_.sensor_losses;
                fails_[i] = 0;
                if (i == 2) mag_seen_ = false;
                continue;
            }
            raw_flags_ |= (uint8_t)(RAW_ACCEL_STALE << i);
        }
        if (i < 2 || mag_seen_) raw_flags_ |= bit;  // RAW_ACCEL_OK, RAW_GYRO_OK, RAW_MAG_OK are the sensor bits
    }
    // a missing sensor's values are 0
    for (uint8_t i = first; i < last; ++i)
        if (!(raw_flags_ & (1u << i))) raw_[i][0] = raw_[i][1] = raw_[i][2] = 0;
}

__attribute__((noinline)) void SphereDevice::handleEvents() {
    uint32_t t_ev;
    if (!hal_.adxlInterrupt(t_ev)) return;
    if (!(sensors_ok_ & SENSOR_ADXL345)) return;
    uint8_t src, act;
    if (!adxl_.readEvent(src, act)) {
        ++status_.i2c_errors[0];  // the interrupt line stays high: read again next period
        return;
    }
    if (src & (Adxl345::INT_SINGLE_TAP | Adxl345::INT_DOUBLE_TAP)) guard_.onTapInterrupt();
    // The chip raises FREE_FALL again after every INT_SOURCE read while the fall lasts: one EVENT per
    // fall, a new one only after FREE_FALL_GAP_US without it.
    uint8_t report = src;
    if (src & Adxl345::INT_FREE_FALL) {
        if (falling_ && t_ev - last_fall_us_ < FREE_FALL_GAP_US) report &= (uint8_t)~Adxl345::INT_FREE_FALL;
        falling_ = true;
        last_fall_us_ = t_ev;
    }
    Event ev[2];
    uint8_t n = tapEvents(t_ev, report, act, guard_, ev);
    for (uint8_t i = 0; i < n; ++i) ev[i].int_source = src;  // the register as read
    uint8_t body[EVENT_LEN];
    for (uint8_t i = 0; i < n; ++i) sendPacket(PKT_EVENT, body, writeEvent(ev[i], body));
}

// The rotation across a gap in the gyroscope's samples, by the trapezoid rule: the rate is taken to go
// linearly from the last fresh sample's ω0 to this one's ω1, so the gap of T should turn the sphere by
// (ω0 + ω1)/2·T. What was integrated instead (the held ω0 for each stale period, nothing while the gyro
// was missing, ω1 for the late part of an overrun) is made good by one extra rotation. Gaps longer than
// GAP_BRIDGE_TICKS are not bridged (the orientation stays as held).
void SphereDevice::bridgeGap(const int16_t g[3], uint16_t dt_us) {
    int16_t c[3];
    uint32_t span = 0;
    for (uint8_t i = 0; i < 3; ++i) {
        int16_t mid = (int16_t)(((int32_t)g_fresh_[i] + g[i]) >> 1);
        if (gap_) {
            // held periods integrated ω0: the rest of the gap's turn at the mean rate over the gap
            c[i] = (int16_t)(mid - (int32_t)g_fresh_[i] * gap_held_ / gap_);
        } else {
            c[i] = (int16_t)(((int32_t)g_fresh_[i] - g[i]) >> 1);  // an overrun: ω1 stood for the late part
        }
        g_fresh_[i] = g[i];
    }
    if (gap_ && gap_ <= GAP_BRIDGE_TICKS) span = (uint32_t)gap_ * MargFilter::DEFAULT_DT_US;
    else if (!gap_ && dt_us > MargFilter::DEFAULT_DT_US) span = dt_us - MargFilter::DEFAULT_DT_US;
    gap_ = gap_held_ = 0;
    if (span) filter_.rotate(c, span);
}

__attribute__((noinline)) void SphereDevice::runFilter(uint16_t dt_us) {
    if (!(raw_flags_ & RAW_GYRO_OK)) {
        // no gyroscope: integrating zeros would turn a moving sphere still; hold the orientation
        gyro_[0] = gyro_[1] = gyro_[2] = 0;
        if (gap_ < 255) ++gap_;
        ori_flags_ = (uint8_t)(ORI_GYRO_MISSING | (converge_left_ ? ORI_CONVERGING : 0) | ((ori_flags_ & 7) << 5));
        return;
    }
    int16_t* g = gyro_;
    int16_t a[3], m[3], up[3];
    applyGyro(cal_, raw_[1], g);
    if (raw_flags_ & RAW_GYRO_STALE) {
        if (gap_ < 255) {  // the held sample is integrated once more
            ++gap_;
            ++gap_held_;
        }
    } else {
        bridgeGap(g, dt_us);
    }
    applyAccel(cal_, raw_[0], a);
    applyMag(cal_, raw_[2], m);
    bool acc_ok = (raw_flags_ & RAW_ACCEL_OK) && !tap_active_ && gates_.accel(a);
    bool mag_present = (raw_flags_ & RAW_MAG_OK) != 0;
    filter_.up(up);
    bool mag_ok = mag_present && !mag_overflow_ && gates_.mag(m, up, converge_left_ != 0);
    hal_.margPin(true);
    uint8_t f = filter_.update(g, a, m, acc_ok, mag_ok, dt_us);
    hal_.margPin(false);
    if (mag_present && !mag_ok) f |= ORI_MAG_REJECTED;
    if (converge_left_) {
        // the start-up gain stays until that many samples actually corrected the orientation
        f |= ORI_CONVERGING;
        if (acc_ok && --converge_left_ == 0) filter_.setBetaMilli(beta_milli_);
    }
    // bits 5-7: the previous update's decisions, so a 100 Hz stream tells every 200 Hz update's inputs
    ori_flags_ = (uint8_t)(f | ((ori_flags_ & 7) << 5));
}

// Power-up and CALIBRATION_STEP estimates take the window's mean; between them every still window of
// TRACK_SAMPLES moves the bias by at most TRACK_STEP_LSB towards its mean (a slow drift with
// temperature is followed, a slow turn mistaken for stillness costs little).
void SphereDevice::trackBias() {
    if (!(raw_flags_ & RAW_GYRO_OK) || (raw_flags_ & (RAW_GYRO_STALE | RAW_ACCEL_STALE))) return;
    if (!bias_est_.running()) {
        if (cal_step_ != 0) return;
        bias_est_.start(TRACK_SAMPLES);
        tracking_ = true;
    }
    int8_t r = bias_est_.update(raw_[1], raw_[0], (raw_flags_ & RAW_MAG_OK) ? raw_[2] : 0);
    if (r > 0) {
        bool full = !tracking_ || !(cal_state_ & CAL_GYRO_BIAS_VALID);
        for (uint8_t i = 0; i < 3; ++i) {
            int16_t d = (int16_t)(bias_est_.bias()[i] - cal_.gyro_bias[i]);
            if (!full) d = d > TRACK_STEP_LSB ? TRACK_STEP_LSB : d < -TRACK_STEP_LSB ? -TRACK_STEP_LSB : d;
            cal_.gyro_bias[i] = (int16_t)(cal_.gyro_bias[i] + d);
        }
        cal_state_ |= CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED;
        cal_state_ &= (uint8_t)~CAL_FROM_EEPROM;
    }
    if (r != 0) {
        if (r < 0 && bias_at_startup_ && bias_tries_ < STARTUP_BIAS_TRIES) {
            ++bias_tries_;
            bias_est_.start(STARTUP_BIAS_SAMPLES);  // moved: try again
        } else {
            bias_at_startup_ = false;
            if (cal_step_ == 1) cal_step_ = 0;
        }
        if (!bias_est_.running()) tracking_ = false;
    }
}

// The record kept over a reset follows the bias in use (tracked, estimated, set, loaded or reset by a
// command): rewritten when it differs, at most once a period.
__attribute__((noinline)) void SphereDevice::keepTrackedBias() {
    KeptBias& k = hal_.keptBias();
    uint8_t bits = (uint8_t)(cal_state_ & (CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED));
    bool same = k.cal_bits == bits;
    for (uint8_t i = 0; i < 3; ++i)
        if (k.gyro_bias[i] != cal_.gyro_bias[i]) same = false;
    if (!same) keepBias(k, cal_.gyro_bias, bits);
}

__attribute__((noinline)) void SphereDevice::tick() {
    uint32_t t0 = hal_.micros();
    // the real interval after an overrun (a period is 5000 µs; the first tick has no predecessor)
    uint32_t since = t0 - last_t_us_;
    uint16_t dt = (last_t_us_ && since > MargFilter::DEFAULT_DT_US * 3 / 2)
                      ? (uint16_t)(since > MargFilter::MAX_DT_US ? MargFilter::MAX_DT_US : since)
                      : 0;
    last_t_us_ = t0;
    watchLink();
    sample_t_us_ = t0;
    readSensors(0, 2);  // the accelerometer, then the gyroscope: the newest reading closest to the send
    if (!link_quiet_) handleEvents();  // an event waits latched in the ADXL345 while nothing may be sent (spec §5.4)
    if (raw_flags_ & RAW_ACCEL_OK) tap_active_ = guard_.update(raw_[0]);
    else tap_active_ = false;
    raw_flags_ = (uint8_t)(tap_active_ ? raw_flags_ | RAW_TAP_ACTIVE : raw_flags_ & ~RAW_TAP_ACTIVE);
    // the sample leaves now, before the magnetometer's poll and the MARG update; it carries the magnetometer
    // as the previous period's poll left it (spec §4.2; firmware/README.md, "How old a sample is")
    streamRaw(t0);
    readSensors(2, 3);
    trackBias();
    keepTrackedBias();
    runFilter(dt);
    stream(t0);
    if (store_cmd_) serviceStore();
    if (++phase_ >= IMU_RATE_HZ) phase_ = 0;

    uint32_t work = hal_.micros() - t0;
    if (work > 0xFFFF) work = 0xFFFF;
    if (work > max_work_us_) max_work_us_ = (uint16_t)work;
}

// RAW_SAMPLE as soon as the chips are read: the host's pointer moves from its gyroscope reading, and the MARG
// update (0.6 ms) and the ORIENTATION frame no longer stand between the read and the sample's first byte.
__attribute__((noinline)) void SphereDevice::streamRaw(uint32_t t_us) {
    if (!(stream_mode_ & STREAM_RAW) || !raw_rate_hz_ || phase_ % (IMU_RATE_HZ / raw_rate_hz_) != 0) return;
    RawSample r;
    r.t_us = t_us;
    r.flags = (uint8_t)(raw_flags_ | (mag_fresh_since_raw_ ? RAW_MAG_FRESH : 0));
    for (uint8_t i = 0; i < 3; ++i) {
        r.accel[i] = raw_[0][i];
        r.gyro[i] = raw_[1][i];
        r.mag[i] = raw_[2][i];
    }
    mag_fresh_since_raw_ = false;
    uint8_t body[RAW_SAMPLE_LEN];
    sendPacket(PKT_RAW_SAMPLE, body, writeRawSample(r, body));
}

// ORIENTATION after the update, STATUS once a second.
__attribute__((noinline)) void SphereDevice::stream(uint32_t t_us) {
    uint8_t body[STATUS_LEN];
    if ((stream_mode_ & STREAM_ORIENTATION) && orientation_rate_hz_ &&
        phase_ % (IMU_RATE_HZ / orientation_rate_hz_) == 0) {
        Orientation o;
        o.t_us = t_us;
        o.flags = ori_flags_;
        orientationQ14(o.quat);
        sendPacket(PKT_ORIENTATION, body, writeOrientation(o, body));
    }
    if ((stream_mode_ & STREAM_STATUS) && phase_ == IMU_RATE_HZ / 2) sendStatus();
}

void SphereDevice::sendPacket(uint8_t type, const uint8_t* body, uint8_t len) {
    if (link_quiet_) return;  // a rate the host may not listen at yet: not sent, no sequence number (spec §5.4)
    uint8_t frame[MAX_FRAME];
    uint8_t n = (uint8_t)FrameEncoder::encodeWithSeq(type, encoder_.nextSeq(), body, len, frame);
    // a dropped frame still uses its sequence number, so the host sees the loss as a gap
    encoder_.setNextSeq((uint8_t)(encoder_.nextSeq() + 1));
    if (!n || !hal_.send(frame, n)) ++status_.frames_dropped;
}

void SphereDevice::sendHello() {
    Hello h;
    h.protocol_version = PROTOCOL_VERSION;
    h.firmware_version[0] = FIRMWARE_VERSION_MAJOR;
    h.firmware_version[1] = FIRMWARE_VERSION_MINOR;
    h.firmware_version[2] = FIRMWARE_VERSION_PATCH;
    h.sensors_found = sensors_found_;
    h.adxl345_devid = adxl_.devid();
    h.itg3200_whoami = itg_.whoami();
    for (uint8_t i = 0; i < 3; ++i) h.hmc5883l_id[i] = hmc_.id()[i];  // as read at 0x1E (zeros: no answer)
    h.imu_rate_hz = IMU_RATE_HZ;
    h.mag_rate_hz = mag_chip_ == MAG_CHIP_QMC5883L ? 100 : Hmc5883l::RATE_HZ;
    h.stream_mode = stream_mode_;
    h.raw_rate_hz = raw_rate_hz_;
    h.orientation_rate_hz = orientation_rate_hz_;
    h.calibration_state = cal_state_;
    h.reset_cause = reset_cause_;
    h.mag_chip = mag_chip_;
    h.board_profile = board_profile_;
    uint8_t body[HELLO_LEN];
    sendPacket(PKT_HELLO, body, writeHello(h, body));
}

void SphereDevice::sendStatus() {
    status_.t_us = hal_.micros();
    status_.sensors_ok = sensors_ok_;
    status_.i2c_recoveries = hal_.i2cRecoveries();
    status_.rx_errors = (uint16_t)(decoder_.oversize + decoder_.framing_errors + decoder_.crc_errors);
    status_.calibration_state = cal_state_;
    status_.calibration_step = cal_step_;
    status_.cpu_load = max_work_us_ / (MargFilter::DEFAULT_DT_US / 1000u);  // µs per 5 ms → per mille
    max_work_us_ = 0;
    status_.battery_mv = hal_.batteryMv();
    uint8_t body[STATUS_LEN];
    sendPacket(PKT_STATUS, body, writeStatus(status_, body));
}

__attribute__((noinline)) bool SphereDevice::receive(uint8_t byte) {
    // a delimiter ends a command: take it only when its reply fits (it waits in the receive buffer)
    if (byte == 0 && decoder_.pending() && hal_.txRoom() < REPLY_ROOM) return false;
    if (decoder_.push(byte) == FRAME_OK) {
        rx_t_us_ = hal_.micros();
        rx_idle_ticks_ = 0;
        link_quiet_ = false;  // the host's first intact frame at a new rate confirms it (spec §5.4)
        execute(decoder_.payload(), decoder_.payloadLength());
    }
    return true;
}

// SET_BAUD (spec §5.4): the REPLY leaves at the old rate, then nothing is sent until the host's first intact
// frame at the new one; watchLink() falls back to the default rate when that, or a later frame, does not come.
void SphereDevice::switchBaud(uint32_t baud) {
    hal_.setBaud(baud);
    baud_ = baud == DEFAULT_BAUD ? 0 : baud;
    link_quiet_ = true;
    rx_idle_ticks_ = 0;
}

void SphereDevice::watchLink() {
    if (!baud_ && !link_quiet_) return;
    if (++rx_idle_ticks_ < (link_quiet_ ? BAUD_CONFIRM_TICKS : BAUD_LEASE_TICKS)) return;
    // nobody confirmed or renewed the rate: back to the one every host starts at, a 0x00 to end what it cut
    hal_.setBaud(DEFAULT_BAUD);
    baud_ = 0;
    link_quiet_ = false;
    rx_idle_ticks_ = 0;
    uint8_t zero = 0;
    hal_.send(&zero, 1);
}

__attribute__((noinline)) void SphereDevice::execute(const uint8_t* payload, uint8_t len) {
    Command c;
    uint8_t result = CommandParser::parse(payload, len, c);
    if (result == RESULT_OK) result = executeCommand(c);
    keepTrackedBias();
    if (result == RESULT_LATER) return;  // the REPLY follows when the EEPROM holds the block (finishStore)  // a command that changed the bias is kept at once: a REBOOT may follow in this period
    uint8_t body[REPLY_CALIBRATION_LEN];
    uint8_t n;
    if (result == RESULT_OK && c.type == CMD_ECHO) {
        uint8_t data[4];
        putU32(data, rx_t_us_);
        n = writeReply(c.seq, c.type, result, data, sizeof data, body);
    } else if (result == RESULT_OK && c.type == CMD_GET_CALIBRATION) {
        uint8_t data[CALIBRATION_BLOCK_LEN + 1];
        writeCalibrationBlock(cal_, data);
        data[CALIBRATION_BLOCK_LEN] = cal_state_;
        n = writeReply(c.seq, c.type, result, data, sizeof data, body);
    } else if (result == RESULT_OK && c.type == CMD_GET_SETTINGS) {
        uint8_t data[SETTINGS_BLOCK_LEN + 1];
        settingsBlock(data);
        data[SETTINGS_BLOCK_LEN] = settings_state_;
        n = writeReply(c.seq, c.type, result, data, sizeof data, body);
    } else {
        n = writeReply(c.seq, c.type, result, 0, 0, body);
    }
    sendPacket(PKT_REPLY, body, n);
    if (result != RESULT_OK) return;
    if (c.type == CMD_GET_HELLO) sendHello();
    else if (c.type == CMD_GET_STATUS) sendStatus();
    else if (c.type == CMD_REBOOT) hal_.reboot();
    else if (c.type == CMD_SET_BAUD && c.set_baud.baud != baud()) switchBaud(c.set_baud.baud);
}

// Stops the power-up gyro bias estimate or a CALIBRATION_STEP gyro_bias, whichever runs.
void SphereDevice::endBiasEstimate() {
    bias_est_.stop();  // a tracking window too: it restarts from the new bias
    tracking_ = false;
    bias_at_startup_ = false;
    if (cal_step_ == 1) cal_step_ = 0;
}

__attribute__((noinline)) uint8_t SphereDevice::executeCommand(const Command& c) {
    switch (c.type) {
        case CMD_SET_STREAM:
            stream_mode_ = c.set_stream.stream_mode;
            raw_rate_hz_ = c.set_stream.raw_rate_hz;
            orientation_rate_hz_ = c.set_stream.orientation_rate_hz;
            settings_state_ &= (uint8_t)~SETTINGS_SAVED;
            return RESULT_OK;
        case CMD_SET_TAP: {
            if (!(sensors_ok_ & SENSOR_ADXL345)) return RESULT_SENSOR_MISSING;
            TapSettings t = {c.set_tap.thresh_tap, c.set_tap.dur, c.set_tap.latent, c.set_tap.window,
                             c.set_tap.tap_axes};
            if (!adxl_.writeTap(t)) {
                ++status_.i2c_errors[0];
                adxl_.writeTap(tap_);  // best effort: back to the settings in use
                return RESULT_FAILED;
            }
            tap_ = t;
            guard_.setThreshold(t.thresh_tap);
            settings_state_ &= (uint8_t)~SETTINGS_SAVED;
            return RESULT_OK;
        }
        case CMD_SET_FREE_FALL: {
            if (!(sensors_ok_ & SENSOR_ADXL345)) return RESULT_SENSOR_MISSING;
            FreeFallSettings f = {c.set_free_fall.thresh_ff, c.set_free_fall.time_ff};
            if (!adxl_.writeFreeFall(f)) {
                ++status_.i2c_errors[0];
                adxl_.writeFreeFall(ff_);
                return RESULT_FAILED;
            }
            ff_ = f;
            settings_state_ &= (uint8_t)~SETTINGS_SAVED;
            return RESULT_OK;
        }
        case CMD_SET_FILTER:
            beta_milli_ = c.set_filter.beta;
            if (!converge_left_) filter_.setBetaMilli(beta_milli_);
            settings_state_ &= (uint8_t)~SETTINGS_SAVED;
            return RESULT_OK;
        case CMD_SAVE_SETTINGS:
        case CMD_CLEAR_SETTINGS: {
            uint8_t image[SETTINGS_EEPROM_LEN];
            if (c.type == CMD_SAVE_SETTINGS) {
                uint8_t block[SETTINGS_BLOCK_LEN];
                settingsBlock(block);
                writeSettingsImage(block, image);
            } else {
                memset(image, 0xFF, sizeof image);  // an erased block: the next power-up uses the defaults
            }
            return startStore(c, SETTINGS_EEPROM_ADDR, image, SETTINGS_EEPROM_LEN);
        }
        case CMD_CALIBRATION_STEP: {
            uint8_t step = c.calibration_step.step;
            if (c.calibration_step.action == 0) {  // stop ends any step
                endBiasEstimate();
                cal_step_ = 0;
                return RESULT_OK;
            }
            if (cal_step_ != 0 && cal_step_ != step) return RESULT_BUSY;
            static const uint8_t needs[4] = {0, SENSOR_ITG3200, SENSOR_ADXL345, SENSOR_HMC5883L};
            if (!(sensors_ok_ & needs[step])) return RESULT_SENSOR_MISSING;
            cal_step_ = step;
            if (step == 1) {
                bias_at_startup_ = false;
                tracking_ = false;
                bias_est_.start(STEP_BIAS_SAMPLES);
            }
            return RESULT_OK;
        }
        case CMD_SET_CALIBRATION:
            endBiasEstimate();  // the block's bias is the host's word: an estimate finishing later must not replace it
            cal_ = c.calibration;
            cal_state_ = (uint8_t)((cal_state_ & ~(CAL_FROM_EEPROM | CAL_GYRO_BIAS_ESTIMATED)) | CAL_GYRO_BIAS_VALID);
            updateCalState();
            return RESULT_OK;
        case CMD_SAVE_CALIBRATION: {
            uint8_t image[CALIBRATION_EEPROM_LEN];
            writeCalibrationImage(cal_, image);
            return startStore(c, 0, image, CALIBRATION_EEPROM_LEN);
        }
        case CMD_LOAD_CALIBRATION: {
            if (store_cmd_) return RESULT_BUSY;  // the EEPROM holds half of a block
            uint8_t image[CALIBRATION_EEPROM_LEN];
            hal_.eepromRead(0, image, CALIBRATION_EEPROM_LEN);
            Calibration cal;
            if (!readCalibrationImage(image, cal)) return RESULT_STORAGE_ERROR;
            endBiasEstimate();
            cal_ = cal;
            cal_state_ = (uint8_t)((cal_state_ & ~(CAL_EEPROM_INVALID | CAL_GYRO_BIAS_ESTIMATED)) | CAL_FROM_EEPROM |
                                   CAL_GYRO_BIAS_VALID);
            updateCalState();
            return RESULT_OK;
        }
        case CMD_RESET_CALIBRATION:
            cal_.setDefaults();
            cal_state_ &= (uint8_t)~(CAL_FROM_EEPROM | CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED);
            updateCalState();
            return RESULT_OK;
        case CMD_IDENTIFY:
            hal_.identify(c.identify.seconds);
            return RESULT_OK;
        case CMD_SET_BOARD: {
            uint8_t b[2] = {c.set_board.board_profile, (uint8_t)~c.set_board.board_profile};
            return startStore(c, BOARD_EEPROM_ADDR, b, 2);
        }
        case CMD_REBOOT:
            return store_cmd_ ? RESULT_BUSY : RESULT_OK;  // not with a block half written
        default:  // GET_HELLO, GET_CALIBRATION, GET_STATUS: the reply and what follows it
            return RESULT_OK;
    }
}

// Starts writing a block to the EEPROM (the calibration, the board profile, the settings); the command's REPLY
// is sent by finishStore. One block at a time.
uint8_t SphereDevice::startStore(const Command& c, uint16_t addr, const uint8_t* data, uint8_t len) {
    if (store_cmd_) return RESULT_BUSY;
    store_cmd_ = c.type;
    store_seq_ = c.seq;
    store_addr_ = addr;
    store_len_ = len;
    store_pos_ = 0;
    memcpy(store_buf_, data, len);
    serviceStore();  // bytes already as they should be cost nothing; the first that differs starts now
    return RESULT_LATER;
}

// Writes the block's next byte that differs from the EEPROM's whenever the EEPROM is ready (on the AVR one a
// period: a byte takes 3.4 ms), then reads the block back and answers the command.
__attribute__((noinline)) void SphereDevice::serviceStore() {
    while (hal_.eepromReady()) {
        if (store_pos_ < store_len_) {
            uint8_t now;
            uint16_t a = (uint16_t)(store_addr_ + store_pos_);
            hal_.eepromRead(a, &now, 1);
            if (now != store_buf_[store_pos_] && !hal_.eepromWriteByte(a, store_buf_[store_pos_])) {
                finishStore(RESULT_STORAGE_ERROR);
                return;
            }
            ++store_pos_;
            continue;
        }
        if (hal_.txRoom() < REPLY_ROOM) return;  // the REPLY must not be dropped: next period
        uint8_t result = RESULT_OK;
        for (uint8_t i = 0; i < store_len_; ++i) {
            uint8_t back;
            hal_.eepromRead((uint16_t)(store_addr_ + i), &back, 1);
            if (back != store_buf_[i]) result = RESULT_STORAGE_ERROR;
        }
        finishStore(result);
        return;
    }
}

void SphereDevice::finishStore(uint8_t result) {
    uint8_t cmd = store_cmd_;
    store_cmd_ = 0;
    if (result == RESULT_OK) {
        if (cmd == CMD_SAVE_CALIBRATION) {
            cal_state_ = (uint8_t)((cal_state_ & ~CAL_EEPROM_INVALID) | CAL_FROM_EEPROM);
        } else if (cmd == CMD_SAVE_SETTINGS || cmd == CMD_CLEAR_SETTINGS) {
            settings_state_ = cmd == CMD_SAVE_SETTINGS ? SETTINGS_SAVED : SETTINGS_NONE_SAVED;
        } else if (board_profile_ != store_buf_[0]) {  // SET_BOARD
            // another frame for the samples: the orientation and the field reference start again
            board_profile_ = store_buf_[0];
            filter_.begin(MargFilter::DEFAULT_DT_US);
            filter_.setBetaMilli(MargFilter::STARTUP_BETA_MILLI);
            converge_left_ = STARTUP_CONVERGE_SAMPLES;
            gates_.reset();
            // the bias was measured in the old frame (a GY-85's gyro x and y change sign): not valid, so
            // the next still window sets it whole and a warm reset does not bring it back (kept_bias.h)
            cal_state_ &= (uint8_t)~CAL_GYRO_BIAS_VALID;
            keepTrackedBias();
        }
    }
    uint8_t body[REPLY_CALIBRATION_LEN];
    sendPacket(PKT_REPLY, body, writeReply(store_seq_, cmd, result, 0, 0, body));
}

}  // namespace sphere
