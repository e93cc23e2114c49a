/* handrig reference glove firmware (Arduino sketch).
 *
 * Five analog sensors sampled on a hardware timer (200 Hz), a BNO055
 * IMU on I2C when present, a relax button, sent as firmware_protocol/SPEC.md frames
 * over the serial port. Settings: glove_config.h. Build guide: firmware/README.md.
 *
 * Keeps going on bad hardware: no IMU or an IMU that stops answering sends frames
 * without the quaternion and with a flag, and is looked for again every second; a
 * sensor pinned at 0 or full scale is flagged; the watchdog restarts a hung loop;
 * the LED blinks the state (glove_core.c, gc_led_level).
 */
#include <Wire.h> /* for the Arduino IDE to link the Wire library (board_i2c_wire.cpp) */

#include "board.h"
#include "glove_config.h"
#include "glove_core.h"

/* BNO055 registers (datasheet section 4.3) */
#define BNO_CHIP_ID 0x00
#define BNO_CHIP_ID_VALUE 0xA0
#define BNO_QUA_DATA_W_LSB 0x20
#define BNO_CALIB_STAT 0x35
#define BNO_OPR_MODE 0x3D
#define BNO_MODE_NDOF 0x0C
#define BNO_PAGE_ID 0x07

static uint8_t wire[GC_MAX_WIRE];
static uint16_t sums[GLOVE_N_CHANNELS];
static uint16_t channels[GLOVE_N_CHANNELS];
static int16_t quat[4];
static uint8_t quat_ok;
static gc_debounce button;
static gc_rails rails;
static uint16_t seq;
static uint32_t frames;
static uint8_t base_flags;

static gc_imu_state imu_state = GC_IMU_ABSENT;
static uint8_t imu_fails;
static uint16_t imu_wait; /* frames until the next attempt or until fusion runs */
static uint8_t imu_calibrated;

/* One IMU step per frame, before the tick, so no frame waits for it. */
static void imu_step(void) {
    uint8_t buf[8];
    quat_ok = 0;
    if (imu_wait) {
        imu_wait--;
        return;
    }
    switch (imu_state) {
    case GC_IMU_ABSENT:
        if (board_i2c_read(GLOVE_IMU_ADDR, BNO_CHIP_ID, buf, 1) && buf[0] == BNO_CHIP_ID_VALUE &&
            board_i2c_write(GLOVE_IMU_ADDR, BNO_PAGE_ID, 0) &&
            board_i2c_write(GLOVE_IMU_ADDR, BNO_OPR_MODE, BNO_MODE_NDOF)) {
            imu_state = GC_IMU_STARTING;
            imu_wait = (uint16_t)(GLOVE_RATE_HZ / 50 + 1); /* 7 ms to leave CONFIGMODE */
        } else {
            imu_wait = GLOVE_IMU_RETRY_FRAMES;
        }
        imu_fails = 0;
        return;
    case GC_IMU_STARTING:
    case GC_IMU_RUNNING:
        if (!board_i2c_read(GLOVE_IMU_ADDR, BNO_QUA_DATA_W_LSB, buf, 8)) {
            if (++imu_fails >= GLOVE_IMU_FAILS_LOST) {
                imu_state = GC_IMU_ABSENT; /* a BNO055 plugged back needs NDOF again */
                imu_wait = GLOVE_IMU_RETRY_FRAMES;
            }
            return;
        }
        imu_fails = 0;
        uint8_t first = imu_state != GC_IMU_RUNNING;
        imu_state = GC_IMU_RUNNING;
        quat_ok = gc_quat_from_bno055(buf, quat);
        if ((first || frames % GLOVE_RATE_HZ == 0) &&
            board_i2c_read(GLOVE_IMU_ADDR, BNO_CALIB_STAT, buf, 1))
            imu_calibrated = (buf[0] >> 6) != 0; /* system calibration 1..3 */
        return;
    }
}

void setup() {
    Serial.begin(GLOVE_BAUD);
    board_init(GLOVE_RATE_HZ);
    base_flags = board_reset_by_watchdog() ? GC_FLAG_WATCHDOG_RESET : 0;
    board_led(1);
    const uint8_t delimiter = 0x00; /* SPEC.md section 2: delimit the first frame */
    board_uart_send(&delimiter, 1);
    board_watchdog_start();
}

/* Per period: the IMU is read GLOVE_IMU_LEAD_US before the tick; the tick starts the ADC
 * burst and the frame's head (everything before the channels, stamped with the burst's
 * middle) goes on the wire while the burst runs; each channel is added to the frame as
 * its sample is complete (and any bytes it makes final are sent), so when the burst ends
 * only the last channel, the CRC and the delimiter are left to build, and the rest of the
 * frame follows on the wire byte after byte (board_uart_send). */
static gc_stream stream;
static uint8_t sent; /* wire bytes of this frame handed to the UART */
static uint8_t channels_added;
static uint8_t frame_flags;
static uint16_t pinned_mask; /* from the last frame's channels */

void loop() {
    uint32_t mid_us;
    uint8_t missed;
    if (board_imu_due()) imu_step();
    if (board_burst_started(&mid_us, &missed)) {
        uint8_t flags = base_flags;
        if (imu_state == GC_IMU_ABSENT) flags |= GC_FLAG_IMU_ABSENT;
        else if (quat_ok && !imu_calibrated) flags |= GC_FLAG_IMU_UNCALIBRATED;
        if (pinned_mask) flags |= GC_FLAG_SENSOR_RAIL;
        if (missed) flags |= GC_FLAG_OVERRUN;
        uint8_t buttons = gc_debounce_update(&button, board_button_pressed(), GLOVE_DEBOUNCE_FRAMES);
        gc_frame f = {flags, seq++, mid_us, buttons, GLOVE_N_CHANNELS, channels,
                      quat_ok ? quat : (const int16_t *)0};
        sent = (uint8_t)gc_frame_head(&stream, wire, &f);
        board_uart_send(wire, sent);
        frame_flags = flags;
        channels_added = 0;
    }
    uint8_t final = board_burst_final(sums);
    if (final > channels_added) {
        uint8_t k = (uint8_t)(final - channels_added);
        gc_decimate(sums + channels_added, k, GLOVE_OVERSAMPLE_LOG2, channels + channels_added);
        channels_added = final;
        if (final < GLOVE_N_CHANNELS) {
            /* a zero byte in these channels makes the bytes before it final: send them */
            uint8_t ready = (uint8_t)gc_frame_channels(&stream, wire, k, channels + final - k);
            board_uart_send(wire + sent, (uint8_t)(ready - sent));
            sent = ready;
        } else {
            uint8_t n = (uint8_t)gc_frame_tail(&stream, wire, k, channels + final - k);
            board_uart_send(wire + sent, (uint8_t)(n - sent));
            board_test_point(0);
            pinned_mask = gc_rails_update(&rails, channels, GLOVE_N_CHANNELS, 4095, GLOVE_RAIL_FRAMES);
            board_led(gc_led_level(frame_flags, frames, GLOVE_RATE_HZ));
            frames++;
            board_watchdog_feed();
            return;
        }
    }
    board_idle();
}
