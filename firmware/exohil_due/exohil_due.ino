/*
 * exohil_due: reference firmware for the shoulder exosuit's Arduino Due.
 *
 * Samples the four string potentiometers (F, SF, SR, R on A0..A3, 12-bit analogRead),
 * converts each to tendon length in 0.01 mm with a per-channel linear calibration, and
 * streams wire protocol v1 (docs/wire-protocol.md, encoder in exohil_wire.h) at 250 Hz over
 * the native USB port (SerialUSB, /dev/ttyACM* on the host).
 *
 * Timing: absolute micros() deadlines, so the mean rate does not drift with loop overhead.
 * The sequence number counts 4 ms periods: when an iteration overruns (the loop was late by
 * one period or more), the deadline skips ahead to the next period still in the future and
 * the skipped periods are added to seq, so the host sees them as dropped frames (a gap, never
 * a catch-up burst). The wait is bounded by one period, so a stall of any length (even past
 * the 2^32 us micros() wrap, ~71.6 min) costs only the stall itself.
 *
 * Sending never waits on the host (SAM core, ArduinoCore-sam cores/arduino/USB/CDC.cpp):
 * `if (SerialUSB)` is not used in loop() because Serial_::operator bool() calls delay(10)
 * on every call (the loop would run at ~99 Hz); SerialUSB.dtr() reads the same line state
 * without delay. availableForWrite() always reports 511 on this core and USBD_Send/UDD_Send
 * spin until the CDC IN endpoint's single bank is free, with no timeout, so the sketch checks
 * that bank (TXINI, the flag UDD_Send waits on) itself: a frame sampled while no host has the
 * port open, or while the previous USB packet has not been collected (host not reading), is
 * dropped; seq still advances, so the host sees the loss as a gap.
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

// Whether SerialUSB.write() of one small frame returns at once: a host has the port open
// (DTR; write() drops bytes otherwise) and the CDC IN endpoint's bank is free (UDD_Send
// would otherwise spin until the host collects the previous packet).
static bool usbCanSend()
{
    return SerialUSB.dtr() && (UOTGHS->UOTGHS_DEVEPTISR[CDC_TX] & UOTGHS_DEVEPTISR_TXINI) != 0;
}

void setup()
{
    analogReadResolution(12);
    SerialUSB.begin(0);  // native USB CDC: the baud rate is ignored
    deadline_us = micros() + kPeriodUs;
}

void loop()
{
    // Wait for the deadline: at most one period ahead (wrap-safe; anything else is late).
    while (exohil_pace_wait(deadline_us, micros(), kPeriodUs)) {
    }
    uint32_t t_us = micros();
    // Periods elapsed since the last frame: 1 on time, more after an overrun (skipped).
    uint32_t periods = exohil_pace_advance(&deadline_us, t_us, kPeriodUs);
    seq = (uint16_t)(seq + periods - 1u);  // skipped periods show up as dropped frames

    uint16_t values[kSensorCount];
    for (uint8_t i = 0; i < kSensorCount; ++i) {
        values[i] = countsToCentiMm(i, (uint32_t)analogRead(kPins[i]));
    }

    uint8_t frame[EXOHIL_MAX_FRAME_BYTES];
    size_t n = exohil_frame_encode(seq, t_us, values, kSensorCount, frame);
    if (usbCanSend()) {
        SerialUSB.write(frame, n);
    }
    ++seq;  // counts periods, sent or not: gaps tell the host what was lost
}
