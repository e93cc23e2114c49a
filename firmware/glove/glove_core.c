/* handrig glove firmware: the portable core (see glove_core.h). */
#include "glove_core.h"

#if defined(__AVR__)
#include <util/crc16.h>
#endif

uint16_t gc_crc16(const uint8_t *p, size_t n) {
    /* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection (SPEC.md section 4) */
    uint16_t crc = 0xFFFF;
    while (n--) {
#if defined(__AVR__)
        /* avr-libc's XMODEM step is this CRC's step (same polynomial, MSB first) */
        crc = _crc_xmodem_update(crc, *p++);
#else
        crc ^= (uint16_t)((uint16_t)(*p++) << 8);
        for (uint8_t b = 0; b < 8; b++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
#endif
    }
    return crc;
}

size_t gc_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst) {
    size_t code_at = 0, out = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (src[i] == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        } else {
            dst[out++] = src[i];
            code++;
            if (code == 0xFF) {
                dst[code_at] = code;
                code_at = out++;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    return out;
}

static void put_u16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)(v >> 8);
}

size_t gc_frame_build(uint8_t wire[GC_MAX_WIRE], const gc_frame *f) {
    uint8_t payload[GC_MAX_PAYLOAD];
    uint8_t n = f->n > GC_MAX_CHANNELS ? GC_MAX_CHANNELS : f->n;
    uint8_t flags = (uint8_t)(f->flags & ~GC_FLAG_IMU_VALID);
    if (f->q14) flags |= GC_FLAG_IMU_VALID;
    payload[0] = GC_VERSION;
    payload[1] = flags;
    put_u16(payload + 2, f->seq);
    put_u16(payload + 4, (uint16_t)(f->t_us & 0xFFFF));
    put_u16(payload + 6, (uint16_t)(f->t_us >> 16));
    payload[8] = f->buttons;
    payload[9] = n;
    for (uint8_t i = 0; i < 4; i++)
        put_u16(payload + 10 + 2 * i, f->q14 ? (uint16_t)f->q14[i] : 0);
    for (uint8_t i = 0; i < n; i++) put_u16(payload + 18 + 2 * i, f->channels[i]);
    size_t len = 18 + 2 * (size_t)n;
    put_u16(payload + len, gc_crc16(payload, len));
    len += 2;
    size_t out = gc_cobs_encode(payload, len, wire);
    wire[out++] = 0x00;
    return out;
}

void gc_decimate(const uint16_t *sums, uint8_t n, uint8_t os_log2, uint16_t *out) {
    for (uint8_t i = 0; i < n; i++) {
        uint16_t s = sums[i]; /* at most 16 x 1023 */
        out[i] = os_log2 >= 2 ? (uint16_t)(s >> (os_log2 - 2)) : (uint16_t)(s << (2 - os_log2));
    }
}

uint8_t gc_debounce_update(gc_debounce *d, uint8_t level, uint8_t need) {
    level = level ? 1 : 0;
    if (level == d->state) {
        d->count = 0;
        d->candidate = level;
    } else if (level == d->candidate) {
        if (++d->count >= need) {
            d->state = level;
            d->count = 0;
        }
    } else {
        d->candidate = level;
        d->count = 1;
        if (need <= 1) d->state = level;
    }
    return d->state;
}

uint16_t gc_rails_update(gc_rails *r, const uint16_t *ch, uint8_t n, uint16_t full_scale,
                         uint16_t need) {
    uint16_t mask = 0;
    if (n > GC_MAX_CHANNELS) n = GC_MAX_CHANNELS;
    for (uint8_t i = 0; i < n; i++) {
        uint8_t pinned = ch[i] <= GC_RAIL_LOW || ch[i] >= (uint16_t)(full_scale - GC_RAIL_LOW);
        if (!pinned) {
            r->run[i] = 0;
            continue;
        }
        if (r->run[i] < need) r->run[i]++;
        if (r->run[i] >= need) mask |= (uint16_t)(1u << i);
    }
    return mask;
}

uint8_t gc_quat_from_bno055(const uint8_t reg[8], int16_t out[4]) {
    int16_t w = (int16_t)(reg[0] | (reg[1] << 8));
    int16_t x = (int16_t)(reg[2] | (reg[3] << 8));
    int16_t y = (int16_t)(reg[4] | (reg[5] << 8));
    int16_t z = (int16_t)(reg[6] | (reg[7] << 8));
    /* |q|^2 in Q28; a unit quaternion gives 2^28. Accept 0.8..1.2 */
    int32_t n2 = (int32_t)w * w + (int32_t)x * x + (int32_t)y * y + (int32_t)z * z;
    if (n2 < 214748365L || n2 > 322122547L) return 0;
    out[0] = x;
    out[1] = y;
    out[2] = z;
    out[3] = w;
    return 1;
}

uint8_t gc_led_level(uint8_t flags, uint32_t k, uint16_t rate_hz) {
    if (rate_hz == 0) return 1;
    uint32_t phase = k % rate_hz; /* frames into the current second */
    if (flags & GC_FLAG_WATCHDOG_RESET) return 1;
    if (flags & GC_FLAG_SENSOR_RAIL) {
        uint32_t tenth = rate_hz / 10 ? rate_hz / 10 : 1;
        uint32_t slot = phase / tenth; /* 0..9 */
        return slot == 0 || slot == 2;
    }
    if (flags & GC_FLAG_IMU_ABSENT) {
        uint32_t eighth = rate_hz / 8 ? rate_hz / 8 : 1;
        return (uint8_t)((phase / eighth) % 2 == 0);
    }
    return phase < rate_hz / 2;
}
