/* handrig glove firmware: board layer for other Arduino cores (ESP32, RP2040, ...),
 * written against the Arduino API only (analogRead, micros; I2C in board_i2c_wire.cpp). Not built or run
 * in this project's CI: see firmware/README.md. The sample tick is taken from
 * micros() in loop() rather than a hardware timer, and the ADC samples are read
 * one after the other at the tick (these chips are fast enough for that at 200 Hz),
 * so the whole frame goes out after the burst.
 */
#if !(defined(__AVR_ATmega328P__) || defined(__AVR_ATmega328__) || defined(__AVR_ATmega168__))
#include <Arduino.h>

#include "board.h"
#include "glove_config.h"

static const uint8_t adc_pins[GLOVE_N_CHANNELS] = {A0, A1, A2, A3, A4};
static uint32_t period_us, next_us;
static uint16_t burst[GLOVE_N_CHANNELS];
static uint8_t imu_pending, burst_pending, missed;

void board_init(uint16_t rate_hz) {
    pinMode(GLOVE_BUTTON_PIN, INPUT_PULLUP);
    pinMode(GLOVE_LED_PIN, OUTPUT);
    pinMode(GLOVE_TEST_POINT_PIN, OUTPUT);
    analogReadResolution(10); /* the core scales 10-bit sums to 12 bits */
    board_i2c_begin();
    period_us = 1000000UL / rate_hz;
    next_us = micros() + period_us;
    imu_pending = 1;
}

uint8_t board_imu_due(void) {
    uint32_t lead = GLOVE_IMU_LEAD_US < period_us / 2 ? GLOVE_IMU_LEAD_US : period_us / 2;
    if (imu_pending || (int32_t)(micros() - (next_us - lead)) < 0) return 0;
    imu_pending = 1;
    return 1;
}

uint8_t board_burst_started(uint32_t *mid_us, uint8_t *skipped) {
    uint32_t now = micros();
    if ((int32_t)(now - next_us) < 0) return 0;
    while ((int32_t)(now - next_us) >= (int32_t)period_us) { /* late: skip ticks */
        next_us += period_us;
        if (missed < 255) missed++;
    }
    next_us += period_us;
    imu_pending = 0;
    digitalWrite(GLOVE_TEST_POINT_PIN, HIGH);
    for (uint8_t i = 0; i < GLOVE_N_CHANNELS; i++) burst[i] = 0;
    uint32_t first = micros();
    for (uint8_t r = 0; r < (1u << GLOVE_OVERSAMPLE_LOG2); r++)
        for (uint8_t i = 0; i < GLOVE_N_CHANNELS; i++) burst[i] += (uint16_t)analogRead(adc_pins[i]);
    *mid_us = first + (micros() - first) / 2;
    *skipped = missed;
    missed = 0;
    burst_pending = 1;
    return 1;
}

uint8_t board_burst_final(uint16_t *sums) {
    if (!burst_pending) return 0;
    burst_pending = 0;
    for (uint8_t i = 0; i < GLOVE_N_CHANNELS; i++) sums[i] = burst[i];
    return GLOVE_N_CHANNELS;
}

void board_uart_send(const uint8_t *p, uint8_t n) { Serial.write(p, n); }
uint8_t board_button_pressed(void) { return digitalRead(GLOVE_BUTTON_PIN) == LOW; }
void board_led(uint8_t on) { digitalWrite(GLOVE_LED_PIN, on ? HIGH : LOW); }
void board_test_point(uint8_t on) { digitalWrite(GLOVE_TEST_POINT_PIN, on ? HIGH : LOW); }
/* No portable watchdog API: these cores have their own (esp_task_wdt, rp2040 watchdog). */
void board_watchdog_start(void) {}
void board_watchdog_feed(void) {}
uint8_t board_reset_by_watchdog(void) { return 0; }
void board_idle(void) {}
uint32_t board_millis(void) { return millis(); }

#endif
