/*
 * exohil_due: reference firmware for the shoulder exosuit's Arduino Due.
 *
 * Samples the four string potentiometers (F, SF, SR, R on A0..A3, 12-bit analogRead),
 * converts each to tendon length in 0.01 mm with a per-channel linear calibration, and
 * streams wire protocol v1 (docs/wire-protocol.md, encoder in exohil_wire.h) at 250 Hz over
 * the native USB port (SerialUSB, /dev/ttyACM* on the host).
 *
 * Timing: absolute micros() deadlines (deadline += period), so the mean rate does not drift
 * with loop overhead; the u32 micros() value wraps every 2^32 us (~71.6 min) and all
 * comparisons use wrap-safe signed differences.
 *
 * Like the exohil emulator, the device samples and increments the sequence number whether
 * or not a host is reading; a frame that does not fit in the USB transmit buffer is dropped
 * (never blocks the sampling loop) and shows up on the host as a sequence gap.
 */
#include "exohil_wire.h"

static const uint8_t kSensorCount = 4;
static const uint8_t kPins[kSensorCount] = {A0, A1, A2, A3};  // F, SF, SR, R
static const uint32_t kPeriodUs = 4000;                         // 250 Hz

// Calibration: length [0.01 mm] = offset + count * gain_num / gain_den (12-bit counts).
// Placeholder values for a 0..500 mm string pot starting at 100 mm; set per suit.
static const uint32_t kOffsetCentiMm[kSensorCount] = {10000, 10000, 10000, 10000};
static const uint32_t kGainNum[kSensorCount] = {50000, 50000, 50000, 50000};
static const uint32_t kGainDen = 4095;

static uint16_t seq = 0;
static uint32_t deadline_us = 0;

static uint16_t countsToCentiMm(uint8_t channel, uint32_t counts)
{
    uint32_t value = kOffsetCentiMm[channel] + (counts * kGainNum[channel]) / kGainDen;
    return value > 0xFFFFu ? 0xFFFFu : (uint16_t)value;
}

void setup()
{
    analogReadResolution(12);
    SerialUSB.begin(0);  // native USB CDC: the baud rate is ignored
    deadline_us = micros() + kPeriodUs;
}

void loop()
{
    // Wait for the absolute deadline (wrap-safe).
    while ((int32_t)(micros() - deadline_us) < 0) {
    }
    uint32_t t_us = micros();
    deadline_us += kPeriodUs;

    uint16_t values[kSensorCount];
    for (uint8_t i = 0; i < kSensorCount; ++i) {
        values[i] = countsToCentiMm(i, (uint32_t)analogRead(kPins[i]));
    }

    uint8_t frame[EXOHIL_MAX_FRAME_BYTES];
    size_t n = exohil_frame_encode(seq, t_us, values, kSensorCount, frame);
    if (SerialUSB && (size_t)SerialUSB.availableForWrite() >= n) {
        SerialUSB.write(frame, n);
    }
    ++seq;  // counts sampled frames, sent or not: gaps tell the host what was lost
}
