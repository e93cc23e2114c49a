/* handrig glove firmware: board layer for the ATmega328P (Nano, Uno, Pro Mini).
 *
 * Timer1 in CTC mode ticks at the frame rate; its interrupt stamps the time and
 * starts a burst of ADC conversions, each one's interrupt adding to the channel's
 * sum and starting the next (round robin over the channels, so every channel's
 * samples are spread over the same 2 ms). I2C is the Wire library
 * (board_i2c_wire.cpp), with a timeout.
 */
#if defined(__AVR_ATmega328P__) || defined(__AVR_ATmega328__) || defined(__AVR_ATmega168__)
#include <Arduino.h>
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <avr/wdt.h>

#include "board.h"
#include "glove_config.h"

static const uint8_t adc_inputs[GLOVE_N_CHANNELS] = GLOVE_ADC_INPUTS;
#define OVERSAMPLE (1u << GLOVE_OVERSAMPLE_LOG2)

static volatile uint16_t sums[GLOVE_N_CHANNELS];
static volatile uint8_t adc_channel, adc_round;
static volatile uint8_t burst_running, burst_done, tick_flag, missed;
static volatile uint32_t tick_us;
static uint8_t reset_flags;

/* Runs before main and before the Arduino core's init(): keeps the reset cause and
 * stops a watchdog left running by a watchdog reset (it would reset again in 15 ms). */
void board_early(void) __attribute__((naked, used, section(".init3")));
void board_early(void) {
    reset_flags = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

static void adc_start(uint8_t input) {
    ADMUX = (uint8_t)(_BV(REFS0) | (input & 0x0F)); /* AVcc reference */
    ADCSRA |= _BV(ADSC);
}

ISR(TIMER1_COMPA_vect) {
    if (burst_running || burst_done) { /* the last sample is still being sent */
        if (missed < 255) missed++;
        return;
    }
    PORTB |= _BV(PB0); /* test point (D8) high: the sample starts */
    tick_us = micros();
    tick_flag = 1;
    for (uint8_t i = 0; i < GLOVE_N_CHANNELS; i++) sums[i] = 0;
    adc_channel = 0;
    adc_round = 0;
    burst_running = 1;
    adc_start(adc_inputs[0]);
}

ISR(ADC_vect) {
    sums[adc_channel] += ADC;
    if (++adc_channel == GLOVE_N_CHANNELS) {
        adc_channel = 0;
        if (++adc_round == OVERSAMPLE) {
            burst_running = 0;
            burst_done = 1;
            return;
        }
    }
    adc_start(adc_inputs[adc_channel]);
}

void board_init(uint16_t rate_hz) {
    pinMode(GLOVE_BUTTON_PIN, INPUT_PULLUP);
    pinMode(GLOVE_LED_PIN, OUTPUT);
    pinMode(GLOVE_TEST_POINT_PIN, OUTPUT);
    digitalWrite(GLOVE_TEST_POINT_PIN, LOW);
    /* ADC: prescaler 64 (250 kHz at 16 MHz: 52 us a conversion), interrupt on completion.
     * Digital input buffers off on the analog pins A0..A3 (A6 has none). */
    DIDR0 = 0x0F;
    ADCSRA = (uint8_t)(_BV(ADEN) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1));
    board_i2c_begin();
    /* Timer1: CTC on OCR1A, prescaler 8. 200 Hz: OCR1A = 16e6 / 8 / 200 - 1 = 9999 */
    noInterrupts();
    TCCR1A = 0;
    TCCR1B = (uint8_t)(_BV(WGM12) | _BV(CS11));
    TCNT1 = 0;
    OCR1A = (uint16_t)(F_CPU / 8UL / rate_hz - 1);
    TIMSK1 = _BV(OCIE1A);
    interrupts();
}

uint8_t board_tick(uint32_t *t_us) {
    uint8_t got = 0;
    noInterrupts();
    if (tick_flag) {
        tick_flag = 0;
        *t_us = tick_us;
        got = 1;
    }
    interrupts();
    return got;
}

uint8_t board_burst_done(uint16_t *out, uint8_t *skipped) {
    if (!burst_done) return 0;
    for (uint8_t i = 0; i < GLOVE_N_CHANNELS; i++) out[i] = sums[i];
    noInterrupts();
    *skipped = missed;
    missed = 0;
    burst_done = 0;
    interrupts();
    return 1;
}

uint8_t board_button_pressed(void) { return !(PIND & _BV(PD2)); }
void board_led(uint8_t on) {
    if (on) PORTB |= _BV(PB5);
    else PORTB &= (uint8_t)~_BV(PB5);
}
void board_test_point(uint8_t on) {
    if (on) PORTB |= _BV(PB0);
    else PORTB &= (uint8_t)~_BV(PB0);
}
/* 120 ms: a frame is due every 5 ms and the IMU start-up waits are at most 20 ms. */
void board_watchdog_start(void) { wdt_enable(WDTO_120MS); }
void board_watchdog_feed(void) { wdt_reset(); }
uint8_t board_reset_by_watchdog(void) { return (reset_flags & _BV(WDRF)) != 0; }

void board_idle(void) {
    set_sleep_mode(SLEEP_MODE_IDLE); /* timers, ADC, UART and TWI keep running */
    noInterrupts();
    if (tick_flag || burst_done) {
        interrupts();
        return;
    }
    sleep_enable();
    interrupts();
    sleep_cpu(); /* the instruction after sei always runs: no lost wake-up */
    sleep_disable();
}

uint32_t board_millis(void) { return millis(); }

#endif
