/* handrig glove firmware: the portable core.
 *
 * Everything the host must agree with (framing, CRC, flag bits) lives here and in
 * firmware_protocol/SPEC.md. Plain C99, fixed-width types, no heap, no I/O: the
 * same file is compiled for the chip and natively for the unit test
 * (firmware/tests/test_core.c).
 */
#ifndef GLOVE_CORE_H
#define GLOVE_CORE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define GC_VERSION 1
#define GC_MAX_CHANNELS 16
#define GC_MAX_PAYLOAD (20 + 2 * GC_MAX_CHANNELS)
#define GC_MAX_WIRE (GC_MAX_PAYLOAD + 1 + 1) /* COBS code byte + delimiter: 54 */

/* Payload byte 1, flags (SPEC.md section 3). */
#define GC_FLAG_IMU_VALID 0x01        /* the quaternion fields hold an orientation */
#define GC_FLAG_IMU_ABSENT 0x02       /* no IMU answers (none at start, or it stopped) */
#define GC_FLAG_IMU_UNCALIBRATED 0x04 /* IMU answers, fusion not calibrated yet */
#define GC_FLAG_SENSOR_RAIL 0x08      /* a channel is pinned at 0 or full scale */
#define GC_FLAG_WATCHDOG_RESET 0x10   /* the firmware was restarted by its watchdog */
#define GC_FLAG_OVERRUN 0x20          /* a sample tick was missed since the last frame */

uint16_t gc_crc16(const uint8_t *p, size_t n);
size_t gc_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst);

typedef struct {
    uint8_t flags;          /* GC_FLAG_*; IMU_VALID is set from q14 != NULL */
    uint16_t seq;
    uint32_t t_us;
    uint8_t buttons;
    uint8_t n;              /* channels, at most GC_MAX_CHANNELS */
    const uint16_t *channels;
    const int16_t *q14;     /* x, y, z, w in Q14, or NULL when not valid */
} gc_frame;

/* Builds one frame as it goes on the wire (delimiter included); returns its length.
 * The same bytes as gc_frame_head then gc_frame_tail. */
size_t gc_frame_build(uint8_t wire[GC_MAX_WIRE], const gc_frame *f);

/* A frame built in two steps, so that part of it is on the wire before its samples are
 * known (typically 9 of 32 bytes: up to the buttons byte, when it is 0): gc_frame_head
 * stuffs everything before the channels (version .. quaternion, CRC running) and
 * returns how many wire bytes are final, wire[0..k), ready to send; gc_frame_tail
 * adds the channels, the CRC and the delimiter and returns the frame's length:
 * wire[k..len) are the rest. COBS makes a byte final once the zero that ends its group
 * is seen, so k stops at the head's last zero byte (0 when it has none). */
typedef struct {
    uint8_t out;         /* wire bytes written */
    uint8_t code_at;     /* wire index of the open group's code byte */
    uint8_t code;        /* the open group's length + 1 */
    uint16_t crc;        /* CRC-16/CCITT-FALSE of the payload so far */
} gc_stream;
size_t gc_frame_head(gc_stream *s, uint8_t wire[GC_MAX_WIRE], const gc_frame *f);
size_t gc_frame_tail(gc_stream *s, uint8_t wire[GC_MAX_WIRE], uint8_t n, const uint16_t *channels);
/* gc_frame_tail in pieces, for channels that become final one after another: add n more
 * channels (in order; f->n in all) and return how many wire bytes are final now (as
 * gc_frame_head: more only when these channels hold a zero byte), then gc_frame_end adds
 * the CRC and the delimiter and returns the frame's length. */
size_t gc_frame_channels(gc_stream *s, uint8_t wire[GC_MAX_WIRE], uint8_t n, const uint16_t *channels);
size_t gc_frame_end(gc_stream *s, uint8_t wire[GC_MAX_WIRE]);

/* Oversampling: n channel sums of 2^os_log2 samples of a 10-bit ADC each, scaled to
 * 12 bits (0..4092). os_log2 is 0..4. Inline: with a constant os_log2 (the sketch's) the
 * shift is one instruction pair, not a loop, between the last sample and the send. */
static inline void gc_decimate(const uint16_t *sums, uint8_t n, uint8_t os_log2, uint16_t *out) {
    for (uint8_t i = 0; i < n; i++) {
        uint16_t s = sums[i]; /* at most 16 x 1023 */
        out[i] = os_log2 >= 2 ? (uint16_t)(s >> (os_log2 - 2)) : (uint16_t)(s << (2 - os_log2));
    }
}

/* A level that must hold for `need` calls in a row before it counts (button debounce). */
typedef struct {
    uint8_t state, candidate, count;
} gc_debounce;
uint8_t gc_debounce_update(gc_debounce *d, uint8_t level, uint8_t need);

/* Rails: a channel at <= GC_RAIL_LOW or >= full_scale - GC_RAIL_LOW for `need` calls in
 * a row is pinned (a broken wire or a shorted sensor). Returns the mask of pinned
 * channels (bit i = channel i). 16 counts are 4 steps of a 10-bit ADC: a single sample
 * at a rail stays inside with a step or two of noise (8 counts did not: issue 36). */
#define GC_RAIL_LOW 16
typedef struct {
    uint16_t run[GC_MAX_CHANNELS];
} gc_rails;
uint16_t gc_rails_update(gc_rails *r, const uint16_t *ch, uint8_t n, uint16_t full_scale,
                         uint16_t need);

/* The IMU's state, kept by the caller; the core decides what the frame says. */
typedef enum {
    GC_IMU_ABSENT = 0,   /* never answered, or stopped answering */
    GC_IMU_STARTING,     /* answered, fusion mode being entered */
    GC_IMU_RUNNING,
} gc_imu_state;

/* Quaternion from the BNO055 registers 0x20..0x27 (w, x, y, z, int16 LE, Q14) into
 * x, y, z, w; returns 0 when it is not a unit quaternion (fusion not running yet). */
uint8_t gc_quat_from_bno055(const uint8_t reg[8], int16_t out_xyzw[4]);

/* LED level for frame number k at rate_hz given the frame's flags:
 * slow blink (1 Hz) all well; fast blink (4 Hz) IMU absent; double flash every second
 * when a sensor is pinned; lit solid when the watchdog restarted the firmware. */
uint8_t gc_led_level(uint8_t flags, uint32_t k, uint16_t rate_hz);

#ifdef __cplusplus
}
#endif
#endif
