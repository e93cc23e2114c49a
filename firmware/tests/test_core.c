/* Native unit test of the firmware's portable core (firmware/glove/glove_core.c).
 * Prints the wire bytes of SPEC.md's three examples, one line each (the pytest in
 * tests/firmware/ compares them with SPEC.md), then checks the debounce, rails,
 * BNO055 quaternion and LED logic; exits non-zero on the first failure. */
#include <stdio.h>
#include <string.h>

#include "glove_core.h"

static int failures;
#define CHECK(cond)                                                      \
    do {                                                                 \
        if (!(cond)) {                                                   \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
            failures++;                                                  \
        }                                                                \
    } while (0)

/* The frame as SPEC.md section 7 builds it: the whole payload, its CRC, then COBS. */
static size_t reference_frame(uint8_t *wire, const gc_frame *f) {
    uint8_t payload[GC_MAX_PAYLOAD];
    uint8_t n = f->n > GC_MAX_CHANNELS ? GC_MAX_CHANNELS : f->n;
    payload[0] = GC_VERSION;
    payload[1] = (uint8_t)((f->flags & ~GC_FLAG_IMU_VALID) | (f->q14 ? GC_FLAG_IMU_VALID : 0));
    payload[2] = (uint8_t)f->seq;
    payload[3] = (uint8_t)(f->seq >> 8);
    for (int i = 0; i < 4; i++) payload[4 + i] = (uint8_t)(f->t_us >> (8 * i));
    payload[8] = f->buttons;
    payload[9] = n;
    for (int i = 0; i < 4; i++) {
        uint16_t v = f->q14 ? (uint16_t)f->q14[i] : 0;
        payload[10 + 2 * i] = (uint8_t)v;
        payload[11 + 2 * i] = (uint8_t)(v >> 8);
    }
    for (int i = 0; i < n; i++) {
        payload[18 + 2 * i] = (uint8_t)f->channels[i];
        payload[19 + 2 * i] = (uint8_t)(f->channels[i] >> 8);
    }
    size_t len = 18 + 2 * (size_t)n;
    uint16_t crc = gc_crc16(payload, len);
    payload[len++] = (uint8_t)crc;
    payload[len++] = (uint8_t)(crc >> 8);
    size_t out = gc_cobs_encode(payload, len, wire);
    wire[out++] = 0;
    return out;
}

static uint32_t rng = 2463534242u;
static uint32_t next_random(void) {
    rng ^= rng << 13;
    rng ^= rng >> 17;
    rng ^= rng << 5;
    return rng;
}
/* Mostly zero bytes or mostly not, so that groups of every length occur. */
static uint16_t random_u16(void) {
    uint32_t r = next_random();
    uint16_t v = (uint16_t)(r >> 16);
    if (r & 1) v &= 0xFF00;
    if (r & 2) v &= 0x00FF;
    return v;
}

/* The head's final bytes, sent while the samples are taken, are the reference frame's
 * first bytes and the tail never rewrites them; head + tail is the reference frame. */
static void check_split_build(void) {
    for (int trial = 0; trial < 20000; trial++) {
        uint16_t ch[GC_MAX_CHANNELS + 2];
        int16_t q[4];
        for (int i = 0; i < GC_MAX_CHANNELS + 2; i++) ch[i] = random_u16();
        for (int i = 0; i < 4; i++) q[i] = (int16_t)random_u16();
        uint32_t r = next_random();
        gc_frame f = {(uint8_t)(r & 0x3F), random_u16(),
                      ((uint32_t)random_u16() << 16) | random_u16(), (uint8_t)(r >> 8),
                      (uint8_t)((r >> 16) % (GC_MAX_CHANNELS + 3)), ch, (r >> 24) & 1 ? q : NULL};
        uint8_t want[GC_MAX_WIRE], wire[GC_MAX_WIRE], early[GC_MAX_WIRE];
        size_t n_want = reference_frame(want, &f);
        gc_stream s;
        size_t k = gc_frame_head(&s, wire, &f);
        memcpy(early, wire, k);
        size_t n;
        if (trial % 2) {
            n = gc_frame_tail(&s, wire, f.n, f.channels);
        } else { /* the channels in two pieces, as they become final */
            uint8_t n_ch = f.n > GC_MAX_CHANNELS ? GC_MAX_CHANNELS : f.n;
            uint8_t first = (uint8_t)(next_random() % (n_ch + 1u));
            /* the bytes each piece makes final go on the wire at once: they must be the
             * reference frame's and never be rewritten */
            size_t k1 = gc_frame_channels(&s, wire, first, f.channels);
            uint8_t early1[GC_MAX_WIRE];
            memcpy(early1, wire, k1);
            size_t k2 = gc_frame_channels(&s, wire, (uint8_t)(n_ch - first), f.channels + first);
            uint8_t early2[GC_MAX_WIRE];
            memcpy(early2, wire, k2);
            n = gc_frame_end(&s, wire);
            CHECK(k <= k1 && k1 <= k2 && k2 < n);
            CHECK(memcmp(early1, want, k1) == 0 && memcmp(early2, want, k2) == 0);
        }
        CHECK(n == n_want && k < n);
        CHECK(memcmp(wire, want, n_want) == 0);
        CHECK(memcmp(early, want, k) == 0);
        uint8_t built[GC_MAX_WIRE];
        CHECK(gc_frame_build(built, &f) == n_want && memcmp(built, want, n_want) == 0);
        if (failures) {
            fprintf(stderr, "split build differs at trial %d (n %u, head %u bytes)\n", trial, f.n,
                    (unsigned)k);
            return;
        }
    }
    /* a head whose last zero is the buttons byte: the code byte and the 8 bytes before it are final */
    const uint16_t ch[5] = {0x0101, 0x0101, 0x0101, 0x0101, 0x0101};
    const int16_t q[4] = {0x0101, 0x0101, 0x0101, 0x0101};
    gc_frame f = {0, 0x0101, 0x01010101u, 0, 5, ch, q};
    uint8_t wire[GC_MAX_WIRE];
    gc_stream s;
    CHECK(gc_frame_head(&s, wire, &f) == 9);
}

static void print_wire(const gc_frame *f) {
    uint8_t wire[GC_MAX_WIRE];
    size_t n = gc_frame_build(wire, f);
    for (size_t i = 0; i < n; i++) printf(i ? " %02x" : "%02x", wire[i]);
    printf("\n");
}

int main(void) {
    const uint8_t check[] = "123456789";
    CHECK(gc_crc16(check, 9) == 0x29B1);

    const uint16_t ch1[] = {2048, 1024, 3072, 500, 3500};
    const int16_t q1[] = {0, 0, 0, 16384};
    gc_frame f1 = {0, 1, 1000, 0, 5, ch1, q1};
    print_wire(&f1);
    const uint16_t ch2[] = {0, 65535, 256};
    gc_frame f2 = {0, 65535, 4294967000u, 1, 3, ch2, NULL};
    print_wire(&f2);
    const uint16_t ch3[] = {1000, 2000, 3000, 100, 4095};
    const int16_t q3[] = {8192, -8192, 8192, 8192};
    gc_frame f3 = {0, 42, 123456789u, 5, 5, ch3, q3};
    print_wire(&f3);
    /* status flags ride in byte 1 next to IMU_VALID; IMU_VALID follows q14 only */
    uint8_t wire[GC_MAX_WIRE];
    gc_frame f4 = {GC_FLAG_IMU_ABSENT | GC_FLAG_SENSOR_RAIL | GC_FLAG_IMU_VALID, 7, 0, 0, 1, ch1, NULL};
    size_t n4 = gc_frame_build(wire, &f4);
    CHECK(n4 == 20 + 2 + 1 + 1);
    CHECK(wire[n4 - 1] == 0);
    for (size_t i = 0; i + 1 < n4; i++) CHECK(wire[i] != 0);

    /* oversampling: 8 samples of 1023 -> 4092, of 512 -> 2048 */
    uint16_t sums[2] = {8 * 1023, 8 * 512}, out[2];
    gc_decimate(sums, 2, 3, out);
    CHECK(out[0] == 4092 && out[1] == 2048);
    uint16_t one[1] = {1023};
    gc_decimate(one, 1, 0, out);
    CHECK(out[0] == 4092);

    /* debounce: a level must hold `need` calls; a one-call glitch never counts */
    gc_debounce d;
    memset(&d, 0, sizeof d);
    CHECK(gc_debounce_update(&d, 1, 4) == 0);
    CHECK(gc_debounce_update(&d, 0, 4) == 0);
    for (int i = 0; i < 3; i++) CHECK(gc_debounce_update(&d, 1, 4) == 0);
    CHECK(gc_debounce_update(&d, 1, 4) == 1);
    CHECK(gc_debounce_update(&d, 0, 4) == 1);
    CHECK(gc_debounce_update(&d, 1, 4) == 1);

    /* rails: channel 1 pinned at full scale, channel 2 at 0, after `need` frames */
    gc_rails r;
    memset(&r, 0, sizeof r);
    const uint16_t pins[3] = {2000, 4092, 3};
    uint16_t mask = 0;
    for (int i = 0; i < 99; i++) mask = gc_rails_update(&r, pins, 3, 4095, 100);
    CHECK(mask == 0);
    mask = gc_rails_update(&r, pins, 3, 4095, 100);
    CHECK(mask == 0x6);
    const uint16_t freed[3] = {2000, 4000, 3};
    CHECK(gc_rails_update(&r, freed, 3, 4095, 100) == 0x4);
    /* one sample a step or two of noise off a rail (10-bit 1021 and 2, scaled) stays pinned */
    gc_rails noisy;
    memset(&noisy, 0, sizeof noisy);
    const uint16_t near[2] = {4084, 8};
    for (int i = 0; i < 99; i++) gc_rails_update(&noisy, near, 2, 4095, 100);
    CHECK(gc_rails_update(&noisy, near, 2, 4095, 100) == 0x3);

    /* BNO055 registers w x y z -> x y z w; zeros (fusion not running) are not valid */
    const uint8_t reg[8] = {0x00, 0x20, 0x00, 0xe0, 0x00, 0x20, 0x00, 0x20}; /* .5 -.5 .5 .5 */
    int16_t q[4];
    CHECK(gc_quat_from_bno055(reg, q) == 1);
    CHECK(q[0] == -8192 && q[1] == 8192 && q[2] == 8192 && q[3] == 8192);
    const uint8_t zeros[8] = {0};
    CHECK(gc_quat_from_bno055(zeros, q) == 0);

    /* LED: 1 Hz half duty when well, lit when the watchdog restarted the firmware */
    int lit = 0;
    for (uint32_t k = 0; k < 200; k++) lit += gc_led_level(GC_FLAG_IMU_VALID, k, 200);
    CHECK(lit == 100);
    CHECK(gc_led_level(GC_FLAG_WATCHDOG_RESET, 150, 200) == 1);
    int toggles = 0;
    for (uint32_t k = 1; k < 200; k++)
        toggles += gc_led_level(GC_FLAG_IMU_ABSENT, k, 200) != gc_led_level(GC_FLAG_IMU_ABSENT, k - 1, 200);
    CHECK(toggles == 7); /* 4 Hz: 8 half periods a second */

    check_split_build();

    if (failures) fprintf(stderr, "%d checks failed\n", failures);
    return failures ? 1 : 0;
}
