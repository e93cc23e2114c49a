/* handrig glove firmware: the board layer (pins, ADC, I2C, timer, watchdog).
 * board_avr.cpp drives an ATmega328P's registers; board_arduino.cpp uses only the
 * Arduino API, for other cores (ESP32, RP2040). The UART is Arduino's Serial (begun by
 * the sketch); frames go out through board_uart_send. */
#ifndef GLOVE_BOARD_H
#define GLOVE_BOARD_H

#include <stdint.h>

/* Pins, ADC, the sample timer at rate_hz, I2C at 400 kHz. */
void board_init(uint16_t rate_hz);
/* 1 once per period, GLOVE_IMU_LEAD_US before the next sample tick (and clears it):
 * time to read the IMU, so that no frame waits for I2C. */
uint8_t board_imu_due(void);
/* 1 once per sample tick, when the tick has started its ADC burst (and clears it).
 * *mid_us: the time of the burst's middle (the mean of its samples' times), on the
 * micros() clock; *missed: ticks skipped since the last burst. */
uint8_t board_burst_started(uint32_t *mid_us, uint8_t *missed);
/* How many channels of the burst are final, their sums (2^GLOVE_OVERSAMPLE_LOG2 10-bit
 * samples each) in sums[0..k) (each copied once, when it becomes final: pass the same
 * array every time): channels become final in order during the burst's last round;
 * GLOVE_N_CHANNELS once the burst is complete, returned once (the burst is then over);
 * 0 while none is. */
uint8_t board_burst_final(uint16_t *sums);
/* I2C at 400 kHz (board_i2c_wire.cpp, every core); register access returns 0 on NACK
 * or timeout (never hangs). */
void board_i2c_begin(void);
uint8_t board_i2c_write(uint8_t addr, uint8_t reg, uint8_t value);
uint8_t board_i2c_read(uint8_t addr, uint8_t reg, uint8_t *buf, uint8_t n);
/* Hands the UART n bytes, in order, and returns when the last one is handed over. On
 * the ATmega328P it writes the data register itself as soon as the register is empty
 * (no interrupt a byte: the bytes follow each other with no gap); elsewhere it is
 * Serial.write. The sketch sends every byte through it (a byte left in Serial's buffer
 * could go out after the ones written here). */
void board_uart_send(const uint8_t *p, uint8_t n);
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
