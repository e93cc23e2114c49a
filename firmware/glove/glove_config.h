/* handrig glove firmware: settings. Change them here, then rebuild and flash.
 * Anything the host must agree with (frame layout, flags) is in glove_core.h and
 * firmware_protocol/SPEC.md, not here. */
#ifndef GLOVE_CONFIG_H
#define GLOVE_CONFIG_H

/* Frames per second, one per sensor sample (SPEC.md: 50..500). */
#ifndef GLOVE_RATE_HZ
#define GLOVE_RATE_HZ 200
#endif

/* UART speed. On a 16 MHz AVR 1 Mbps is exact (U2X, UBRR 1) and a 31-byte frame takes
 * 0.31 ms on the wire; 115200 is 2.1 % off and takes 2.7 ms. 8 MHz boards (3.3 V Pro
 * Mini): 500000 is exact. Native-USB boards ignore it. config/glove.toml [glove] baud
 * must say the same. */
#ifndef GLOVE_BAUD
#if defined(F_CPU) && F_CPU == 8000000L
#define GLOVE_BAUD 500000
#else
#define GLOVE_BAUD 1000000
#endif
#endif

/* Five analog sensors in the order of SPEC.md section 3: thumb CMC twist, thumb CMC
 * abduction, thumb CMC flexion, index MCP flexion, little finger MCP flexion. A4/A5
 * are the I2C pins of the IMU, so the fifth sensor is on A6 (Nano, Pro Mini; the Uno
 * has no A6: see firmware/README.md). The numbers are the ADC mux inputs. */
#define GLOVE_N_CHANNELS 5
#define GLOVE_ADC_INPUTS {0, 1, 2, 3, 6}

/* The ADC: its clock is F_CPU / GLOVE_ADC_PRESCALER (8..128) and a conversion takes 13
 * of its clocks; each frame averages 2^GLOVE_OVERSAMPLE_LOG2 samples per channel (0..4),
 * taken round robin over the channels, scaled to 12 bits (0..4092) and stamped with the
 * burst's middle. 128 and 0: 125 kHz (inside the datasheet's 50-200 kHz for 10 bits),
 * one sample per channel, a 0.54 ms burst. Chosen from measured noise: firmware/README.md
 * section 6 and docs/measurements.md (issue 36); more samples or a faster clock trade
 * latency or accuracy for a count or so of noise. */
#ifndef GLOVE_ADC_PRESCALER
#define GLOVE_ADC_PRESCALER 128
#endif
#ifndef GLOVE_OVERSAMPLE_LOG2
#define GLOVE_OVERSAMPLE_LOG2 0
#endif

/* The IMU is read this long before each sample tick, so no frame waits for I2C (an
 * 8-byte read at 400 kHz takes about 0.3 ms; a missing IMU at most the 1 ms timeout). */
#ifndef GLOVE_IMU_LEAD_US
#define GLOVE_IMU_LEAD_US 1000
#endif

/* A channel reading within 16 counts of 0 or full scale for this many frames in a row
 * is flagged as pinned (0.5 s at 200 Hz). */
#define GLOVE_RAIL_FRAMES (GLOVE_RATE_HZ / 2)

/* Relax / e-stop button: pin to ground, internal pull-up; must hold its new level for
 * this many frames (20 ms at 200 Hz). */
#define GLOVE_BUTTON_PIN 2
#define GLOVE_DEBOUNCE_FRAMES 4

#define GLOVE_LED_PIN 13
/* Goes high at each sample tick and low when the frame is handed to the UART: a
 * scope (or the emulator) measures the firmware's latency on it. Leave unconnected. */
#define GLOVE_TEST_POINT_PIN 8

/* BNO055 on I2C at 400 kHz: 0x28 (0x29 with ADR high). */
#define GLOVE_IMU_ADDR 0x28
/* Frames without an answer before the IMU counts as lost, and frames between
 * attempts to find it again. */
#define GLOVE_IMU_FAILS_LOST 3
#define GLOVE_IMU_RETRY_FRAMES GLOVE_RATE_HZ

#endif
