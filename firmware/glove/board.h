/* handrig glove firmware: the board layer (pins, ADC, I2C, timer, watchdog).
 * board_avr.cpp drives an ATmega328P's registers; board_arduino.cpp uses only the
 * Arduino API, for other cores (ESP32, RP2040). The UART is Arduino's Serial. */
#ifndef GLOVE_BOARD_H
#define GLOVE_BOARD_H

#include <stdint.h>

/* Pins, ADC, the sample timer at rate_hz, I2C at 400 kHz. */
void board_init(uint16_t rate_hz);
/* 1 once per sample tick (and clears it); *t_us is the tick's time. */
uint8_t board_tick(uint32_t *t_us);
/* 1 when the tick's ADC burst is complete: sums[] holds 2^GLOVE_OVERSAMPLE_LOG2
 * 10-bit samples per channel; *missed counts ticks skipped since the last burst. */
uint8_t board_burst_done(uint16_t *sums, uint8_t *missed);
/* I2C at 400 kHz (board_i2c_wire.cpp, every core); register access returns 0 on NACK
 * or timeout (never hangs). */
void board_i2c_begin(void);
uint8_t board_i2c_write(uint8_t addr, uint8_t reg, uint8_t value);
uint8_t board_i2c_read(uint8_t addr, uint8_t reg, uint8_t *buf, uint8_t n);
uint8_t board_button_pressed(void);
void board_led(uint8_t on);
void board_test_point(uint8_t on);
void board_watchdog_start(void);
void board_watchdog_feed(void);
uint8_t board_reset_by_watchdog(void);
/* Sleeps until the next interrupt (or returns at once where there is no sleep). */
void board_idle(void);
uint32_t board_millis(void);

#endif
