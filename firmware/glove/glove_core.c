/* handrig glove firmware: the portable core (see glove_core.h). */
#include "glove_core.h"

#if defined(__AVR__)
#include <util/crc16.h>
#endif

/* The frame's last bytes are built between the last sample and the send: the steps a
 * byte takes are inlined where gcc would otherwise call them (-Os). */
#if defined(__GNUC__)
#define GC_INLINE static inline __attribute__((always_inline))
#else
#define GC_INLINE static inline
#endif

/* One CRC-16/CCITT-FALSE step: poly 0x1021, MSB first (SPEC.md section 4) */
GC_INLINE uint16_t crc_step(uint16_t crc, uint8_t b) {
#if defined(__AVR__)
    /* avr-libc's XMODEM step is this CRC's step (same polynomial, MSB first) */
    return _crc_xmodem_update(crc, b);
#else
    crc ^= (uint16_t)((uint16_t)b << 8);
    for (uint8_t k = 0; k < 8; k++)
        crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    return crc;
#endif
}

uint16_t gc_crc16(const uint8_t *p, size_t n) {
    uint16_t crc = 0xFFFF; /* init 0xFFFF, no reflection, no final XOR */
    while (n--) crc = crc_step(crc, *p++);
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

/* The COBS stream's state while bytes are stuffed, kept in a caller's locals (a store
 * through `wire` could otherwise alias gc_stream's fields, on every byte). */
typedef struct {
    uint8_t out, code_at, code;
} cobs_state;

/* gc_cobs_encode's step for one byte, resumable: the wire bytes before the open group's
 * code byte are final. */
GC_INLINE void stuff_byte(uint8_t *wire, cobs_state *c, uint8_t b) {
    if (b == 0) {
        wire[c->code_at] = c->code;
        c->code_at = c->out++;
        c->code = 1;
        return;
    }
    wire[c->out++] = b;
    if (++c->code == 0xFF) { /* never for a version 1 payload (at most 52 bytes) */
        wire[c->code_at] = c->code;
        c->code_at = c->out++;
        c->code = 1;
    }
}

/* n payload bytes onto the stream, the CRC running over them */
static void stream_put(gc_stream *s, uint8_t *wire, const uint8_t *src, uint8_t n) {
    cobs_state c = {s->out, s->code_at, s->code};
    uint16_t crc = s->crc;
    for (uint8_t i = 0; i < n; i++) {
        crc = crc_step(crc, src[i]);
        stuff_byte(wire, &c, src[i]);
    }
    s->out = c.out;
    s->code_at = c.code_at;
    s->code = c.code;
    s->crc = crc;
}

static void put_u16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)(v & 0xFF);
    p[1] = (uint8_t)(v >> 8);
}

size_t gc_frame_head(gc_stream *s, uint8_t wire[GC_MAX_WIRE], const gc_frame *f) {
    uint8_t head[18];
    uint8_t n = f->n > GC_MAX_CHANNELS ? GC_MAX_CHANNELS : f->n;
    uint8_t flags = (uint8_t)(f->flags & ~GC_FLAG_IMU_VALID);
    if (f->q14) flags |= GC_FLAG_IMU_VALID;
    head[0] = GC_VERSION;
    head[1] = flags;
    put_u16(head + 2, f->seq);
    put_u16(head + 4, (uint16_t)(f->t_us & 0xFFFF));
    put_u16(head + 6, (uint16_t)(f->t_us >> 16));
    head[8] = f->buttons;
    head[9] = n;
    for (uint8_t i = 0; i < 4; i++) put_u16(head + 10 + 2 * i, f->q14 ? (uint16_t)f->q14[i] : 0);
    s->out = 1;
    s->code_at = 0;
    s->code = 1;
    s->crc = 0xFFFF;
    stream_put(s, wire, head, sizeof head);
    return s->code_at;
}

/* gc_frame_channels' and gc_frame_end's steps, inlined into each of them and into
 * gc_frame_tail (one call between the last sample and the send) */
GC_INLINE size_t put_channels(gc_stream *s, uint8_t *wire, uint8_t n, const uint16_t *channels) {
    cobs_state c = {s->out, s->code_at, s->code};
    uint16_t crc = s->crc;
    if (n > GC_MAX_CHANNELS) n = GC_MAX_CHANNELS;
    for (uint8_t i = 0; i < n; i++) { /* uint16 little-endian */
        uint8_t lo = (uint8_t)(channels[i] & 0xFF), hi = (uint8_t)(channels[i] >> 8);
        crc = crc_step(crc_step(crc, lo), hi);
        stuff_byte(wire, &c, lo);
        stuff_byte(wire, &c, hi);
    }
    s->out = c.out;
    s->code_at = c.code_at;
    s->code = c.code;
    s->crc = crc;
    return c.code_at;
}

GC_INLINE size_t put_end(gc_stream *s, uint8_t *wire) {
    cobs_state c = {s->out, s->code_at, s->code};
    /* little-endian, not itself part of the CRC */
    stuff_byte(wire, &c, (uint8_t)(s->crc & 0xFF));
    stuff_byte(wire, &c, (uint8_t)(s->crc >> 8));
    wire[c.code_at] = c.code;
    wire[c.out++] = 0x00;
    s->out = c.out;
    s->code_at = c.code_at;
    s->code = c.code;
    return c.out;
}

size_t gc_frame_channels(gc_stream *s, uint8_t wire[GC_MAX_WIRE], uint8_t n, const uint16_t *channels) {
    return put_channels(s, wire, n, channels);
}

size_t gc_frame_end(gc_stream *s, uint8_t wire[GC_MAX_WIRE]) { return put_end(s, wire); }

size_t gc_frame_tail(gc_stream *s, uint8_t wire[GC_MAX_WIRE], uint8_t n, const uint16_t *channels) {
    put_channels(s, wire, n, channels);
    return put_end(s, wire);
}

size_t gc_frame_build(uint8_t wire[GC_MAX_WIRE], const gc_frame *f) {
    gc_stream s;
    gc_frame_head(&s, wire, f);
    return gc_frame_tail(&s, wire, f->n, f->channels);
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
