/*
 * exohil wire protocol v1: frame encoder and period pacing (docs/wire-protocol.md).
 *
 * Plain C99, no Arduino dependencies, static inline only, so the same header builds the
 * Arduino Due sketch and the host-side test driver that checks it against the Python
 * encoder (tests/test_wire_firmware_c.py).
 *
 * Body (little-endian): [0x11][seq u16][t_us u32][count u8][count x u16 0.01 mm][crc u16]
 * CRC-16/CCITT-FALSE over all bytes before it; then COBS; then one 0x00 delimiter.
 */
#ifndef EXOHIL_WIRE_H
#define EXOHIL_WIRE_H

#include <stddef.h>
#include <stdint.h>

#define EXOHIL_TYPE_VERSION 0x11u
#define EXOHIL_MAX_SENSORS 16u
#define EXOHIL_HEADER_SIZE 8u
#define EXOHIL_MAX_BODY_SIZE (EXOHIL_HEADER_SIZE + 2u * EXOHIL_MAX_SENSORS + 2u)
/* COBS code byte + body + 0x00 delimiter (bodies are shorter than 254 bytes). */
#define EXOHIL_MAX_FRAME_BYTES (EXOHIL_MAX_BODY_SIZE + 2u)

/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, xorout 0; "123456789" -> 0x29B1. */
static inline uint16_t exohil_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < len; ++i) {
        crc ^= (uint16_t)((uint16_t)data[i] << 8);
        for (int bit = 0; bit < 8; ++bit) {
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

/* COBS-encode len bytes of in into out (at least len + len / 254 + 1 bytes); no delimiter.
 * Returns the encoded length. */
static inline size_t exohil_cobs_encode(const uint8_t *in, size_t len, uint8_t *out)
{
    size_t code_pos = 0;
    size_t out_pos = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < len; ++i) {
        if (in[i] == 0u) {
            out[code_pos] = code;
            code_pos = out_pos++;
            code = 1;
        } else {
            out[out_pos++] = in[i];
            ++code;
            if (code == 0xFFu) {
                out[code_pos] = code;
                code_pos = out_pos++;
                code = 1;
            }
        }
    }
    out[code_pos] = code;
    return out_pos;
}

static inline void exohil_put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

/* Encode one sensor frame (values in 0.01 mm units) into out, which must hold
 * EXOHIL_MAX_FRAME_BYTES. Returns the number of bytes to send (COBS + 0x00 delimiter),
 * or 0 when count is outside 1..EXOHIL_MAX_SENSORS. */
static inline size_t exohil_frame_encode(uint16_t seq, uint32_t t_us, const uint16_t *values,
                                         uint8_t count, uint8_t *out)
{
    uint8_t body[EXOHIL_MAX_BODY_SIZE];
    if (count < 1u || count > EXOHIL_MAX_SENSORS) {
        return 0;
    }
    body[0] = EXOHIL_TYPE_VERSION;
    exohil_put_u16(&body[1], seq);
    body[3] = (uint8_t)(t_us & 0xFFu);
    body[4] = (uint8_t)((t_us >> 8) & 0xFFu);
    body[5] = (uint8_t)((t_us >> 16) & 0xFFu);
    body[6] = (uint8_t)((t_us >> 24) & 0xFFu);
    body[7] = count;
    size_t n = EXOHIL_HEADER_SIZE;
    for (uint8_t i = 0; i < count; ++i) {
        exohil_put_u16(&body[n], values[i]);
        n += 2u;
    }
    exohil_put_u16(&body[n], exohil_crc16(body, n));
    n += 2u;
    size_t encoded = exohil_cobs_encode(body, n, out);
    out[encoded] = 0x00u;
    return encoded + 1u;
}

/* Pacing (u32 micros(), wrap-safe). Whether to keep waiting for deadline_us at now_us: only
 * while the deadline is 1..period_us ahead. A deadline already reached, or one that looks
 * further ahead (the loop stalled past 2^31 us and the signed difference flipped), is due. */
static inline int exohil_pace_wait(uint32_t deadline_us, uint32_t now_us, uint32_t period_us)
{
    return (uint32_t)(deadline_us - now_us - 1u) < period_us;
}

/* Once due (now_us at or after *deadline_us): move *deadline_us to the first period boundary
 * after now_us and return the periods that elapsed, 1 when on time, 1 + k after an overrun
 * of k whole periods (skipped, never sent late as a burst). Exact for lateness < 2^32 us. */
static inline uint32_t exohil_pace_advance(uint32_t *deadline_us, uint32_t now_us,
                                           uint32_t period_us)
{
    uint32_t periods = (uint32_t)(now_us - *deadline_us) / period_us + 1u;
    *deadline_us += periods * period_us;
    return periods;
}

#endif /* EXOHIL_WIRE_H */
