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

    if (failures) fprintf(stderr, "%d checks failed\n", failures);
    return failures ? 1 : 0;
}
