/* handrig glove firmware: board layer for the ATmega328P (Nano, Uno, Pro Mini).
 *
 * Timer1 in CTC mode ticks at the frame rate. Its compare B interrupt, GLOVE_IMU_LEAD_US
 * before each tick, tells the loop to read the IMU; its compare A interrupt (the tick)
 * stamps the time and starts a burst of ADC conversions, each one's interrupt adding to
 * the channel's sum and starting the next (round robin over the channels, so every
 * channel's samples are spread over the same span and share its middle). The loop
 * sends the frame's head while the burst runs (glove.ino). I2C is the Wire library
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
#define CONVERSIONS (GLOVE_N_CHANNELS * OVERSAMPLE)

/* ADCSRA's ADPS bits: the ADC clock is F_CPU / GLOVE_ADC_PRESCALER */
#if GLOVE_ADC_PRESCALER == 128
#define ADPS_BITS (_BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0))
#elif GLOVE_ADC_PRESCALER == 64
#define ADPS_BITS (_BV(ADPS2) | _BV(ADPS1))
#elif GLOVE_ADC_PRESCALER == 32
#define ADPS_BITS (_BV(ADPS2) | _BV(ADPS0))
#elif GLOVE_ADC_PRESCALER == 16
#define ADPS_BITS (_BV(ADPS2))
#elif GLOVE_ADC_PRESCALER == 8
#define ADPS_BITS (_BV(ADPS1) | _BV(ADPS0))
#else
#error "GLOVE_ADC_PRESCALER must be 8, 16, 32, 64 or 128"
#endif

/* Timer1 runs at F_CPU / 8: 2 counts a microsecond at 16 MHz. */
#define T1_PER_US (F_CPU / 8000000UL)

static volatile uint16_t sums[GLOVE_N_CHANNELS];
static volatile uint8_t adc_channel, adc_round;
static volatile uint8_t burst_running, burst_done, burst_started, imu_due, missed, missed_out;
static volatile uint8_t final_n; /* channels whose sums are complete */
static volatile uint32_t start_us;
/* Timer1 counts at the first and at the last conversion's start: the burst's span */
static volatile uint16_t first_t1, last_t1;
/* the last burst's span in Timer1 counts; before the first one, 13 ADC clocks and about
 * 4 us of interrupt a conversion */
static volatile uint16_t span_t1 =
    (uint16_t)((CONVERSIONS - 1) * (13UL * GLOVE_ADC_PRESCALER / 8 + 4 * T1_PER_US));
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

ISR(TIMER1_COMPB_vect) { imu_due = 1; }

ISR(TIMER1_COMPA_vect) {
    if (burst_running || burst_done || burst_started) { /* the last frame is not out yet */
        if (missed < 255) missed++;
        return;
    }
    PORTB |= _BV(PB0); /* test point (D8) high: the sample starts */
    for (uint8_t i = 0; i < GLOVE_N_CHANNELS; i++) sums[i] = 0;
    adc_channel = 0;
    adc_round = 0;
    final_n = 0;
    burst_running = 1;
    missed_out = missed;
    missed = 0;
    uint32_t us = micros(); /* in 4 us steps: about 2 us before the true time, on average */
    uint16_t us_t1 = TCNT1;
    adc_start(adc_inputs[0]);
    first_t1 = last_t1 = TCNT1;
    start_us = us + 2 + (uint16_t)(first_t1 - us_t1) / T1_PER_US; /* the first conversion's start */
    burst_started = 1;
}

ISR(ADC_vect) {
    sums[adc_channel] += ADC;
    if (adc_round == OVERSAMPLE - 1) final_n = (uint8_t)(adc_channel + 1);
    if (++adc_channel == GLOVE_N_CHANNELS) {
        adc_channel = 0;
        if (++adc_round == OVERSAMPLE) {
            span_t1 = (uint16_t)(last_t1 - first_t1);
            burst_running = 0;
            burst_done = 1;
            return;
        }
    }
    adc_start(adc_inputs[adc_channel]);
    if (adc_round == OVERSAMPLE - 1 && adc_channel == GLOVE_N_CHANNELS - 1) last_t1 = TCNT1;
}

void board_init(uint16_t rate_hz) {
    pinMode(GLOVE_BUTTON_PIN, INPUT_PULLUP);
    pinMode(GLOVE_LED_PIN, OUTPUT);
    pinMode(GLOVE_TEST_POINT_PIN, OUTPUT);
    digitalWrite(GLOVE_TEST_POINT_PIN, LOW);
    /* ADC: clock F_CPU / GLOVE_ADC_PRESCALER, interrupt on completion. Digital input
     * buffers off on the analog pins A0..A3 (A6 has none). */
    DIDR0 = 0x0F;
    ADCSRA = (uint8_t)(_BV(ADEN) | _BV(ADIE) | ADPS_BITS);
    board_i2c_begin();
    /* Timer1: CTC on OCR1A, prescaler 8. 200 Hz: OCR1A = 16e6 / 8 / 200 - 1 = 9999 */
    uint16_t top = (uint16_t)(F_CPU / 8UL / rate_hz - 1);
    uint32_t lead = (uint32_t)GLOVE_IMU_LEAD_US * T1_PER_US;
    noInterrupts();
    TCCR1A = 0;
    TCCR1B = (uint8_t)(_BV(WGM12) | _BV(CS11));
    TCNT1 = 0;
    OCR1A = top;
    OCR1B = (uint16_t)(lead < top / 2 ? top - lead : top / 2);
    TIMSK1 = (uint8_t)(_BV(OCIE1A) | _BV(OCIE1B));
    interrupts();
}

uint8_t board_imu_due(void) {
    if (!imu_due) return 0;
    imu_due = 0;
    return 1;
}

uint8_t board_burst_started(uint32_t *mid_us, uint8_t *skipped) {
    uint8_t got = 0;
    noInterrupts();
    if (burst_started) {
        burst_started = 0;
        /* this burst's middle: its start plus half the last burst's span (the same
         * conversions and interrupts each time: steady to a microsecond) */
        *mid_us = start_us + span_t1 / (2 * T1_PER_US);
        *skipped = missed_out;
        got = 1;
    }
    interrupts();
    return got;
}

static uint8_t copied; /* channels of this burst copied out */

uint8_t board_burst_final(uint16_t *out) {
    uint8_t n = final_n; /* the interrupt no longer adds to sums[0..n) in this burst */
    for (uint8_t i = copied; i < n; i++) out[i] = sums[i];
    copied = n;
    if (n == GLOVE_N_CHANNELS) {
        noInterrupts();
        burst_done = 0;
        final_n = 0;
        interrupts();
        copied = 0;
    }
    return n;
}

/* Polls UDRE0 rather than queueing for Serial's interrupt: at 1 Mbps a byte is 160
 * cycles, and an interrupt a byte (entry, ring buffer, exit) spends half of them; the
 * loop has nothing else to do while a frame's tail goes out. Serial's own buffer is
 * never used (the sketch sends everything here), so nothing can interleave. */
void board_uart_send(const uint8_t *p, uint8_t n) {
    while (n--) {
        while (!(UCSR0A & _BV(UDRE0))) {
        }
        UDR0 = *p++;
    }
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
    if (imu_due || burst_started || burst_done) {
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
