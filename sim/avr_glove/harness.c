/* The glove firmware on an emulated ATmega328P (simavr), wired to a glove recording.
 *
 *   avr_glove FIRMWARE.elf RECORDING.csv [options]
 *
 * Runs the very ELF `make firmware` builds. The harness
 *   - drives the analog inputs from the recording's five raw channels (12-bit counts
 *     -> millivolts at a 5 V reference, with a little noise at each conversion),
 *   - drives the relax button (D2, active low) from the recording's buttons bit 0,
 *   - answers on I2C as a BNO055 at 0x28 (CHIP_ID, OPR_MODE, CALIB_STAT, the
 *     quaternion registers updated at the fusion's 100 Hz from the recording's
 *     forearm orientation, zeros until NDOF mode has run for 7 ms),
 *   - paces the chip to wall-clock time and bridges its UART to a pseudo-terminal,
 *     whose path it prints first: "port: /dev/pts/N".
 * It measures, from outside the firmware, each frame's time from the sample tick
 * (the test point D8 rising) to the frame's last bit on the wire; the frame's ADC burst
 * (the conversions started while D8 is high), its span and its middle (the mean of its
 * conversions' start times: simavr takes the input when a conversion starts), and the
 * time from that middle to the last bit; and the fraction of cycles the CPU was awake.
 * They are printed at the end ("figures: ...").
 *
 * Options:
 *   --seconds S      stop after S s of chip time (default: run until SIGTERM/SIGINT)
 *   --no-imu         no BNO055 on the bus
 *   --imu-off-at S   the BNO055 stops answering at S s (a wire pulled); SIGUSR1 pulls
 *                    it at once
 *   --pin CH=COUNTS  hold raw channel CH at COUNTS (0..4095), e.g. a broken wire
 *   --timing FILE    per frame: its number, the tick and the last byte on CLOCK_MONOTONIC
 *                    (s), tick to last byte (us), the tick in chip time (s), the burst's
 *                    middle to the last byte (us), the middle in chip time (s), the burst's
 *                    span from its first to its last conversion start (us), its conversions,
 *                    the middle on the Arduino core's micros() clock (us since timer 0 was
 *                    started: what the frame's timestamp says when it stamps the middle),
 *                    the frame's bytes sent before its burst's last conversion started
 *   --noise MV       ADC input noise, standard deviation in mV (default 2)
 *   --speed X        chip time runs X times wall time (default 1)
 *   --whole-frames   hand the pty each frame at once when its last byte is out (default:
 *                    each byte as the UART sends it, as a USB-serial chip may)
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_adc.h"
#include "avr_ioport.h"
#include "avr_twi.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_elf.h"
#include "sim_irq.h"
#include "sim_time.h"

#define F_CPU 16000000u
#define N_CH 5
static const int adc_input[N_CH] = {0, 1, 2, 3, 6}; /* firmware/glove/glove_config.h */

/* ---- the recording ---------------------------------------------------------------- */
typedef struct {
    double t_s;
    double raw[N_CH];
    double q[4]; /* x y z w; NaN when the recording has no valid orientation */
    int buttons;
} row_t;
static row_t *rows;
static size_t n_rows;
static double rec_span_s, rec_gap_s;

static void die(const char *what) {
    fprintf(stderr, "avr_glove: %s\n", what);
    exit(2);
}

static void read_recording(const char *path) {
    FILE *f = fopen(path, "r");
    if (!f) {
        perror(path);
        exit(2);
    }
    char line[1024];
    size_t cap = 0;
    int header = 0, has_quat = 0;
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#' || line[0] == '\n') continue;
        if (!header) { /* t_s, 5 channels, [qx qy qz qw,] buttons (handrig/glove_recording.py) */
            int commas = 0;
            for (const char *c = line; *c; c++) commas += *c == ',';
            has_quat = strstr(line, ",qx,qy,qz,qw,") != NULL;
            if (commas != N_CH + 1 + (has_quat ? 4 : 0))
                die("the recording must have t_s, five channels, optionally qx,qy,qz,qw, and buttons");
            header = 1;
            continue;
        }
        if (n_rows == cap) {
            cap = cap ? cap * 2 : 1024;
            rows = realloc(rows, cap * sizeof *rows);
            if (!rows) die("out of memory");
        }
        row_t *r = &rows[n_rows];
        char *p = line, *end;
        r->t_s = strtod(p, &end);
        for (int k = 0; k < N_CH; k++) r->raw[k] = strtod(end + 1, &end);
        for (int k = 0; k < 4; k++) {
            if (!has_quat) {
                r->q[k] = NAN;
                continue;
            }
            p = end + 1;
            r->q[k] = strtod(p, &end);
            if (end == p) r->q[k] = NAN;
        }
        r->buttons = (int)strtol(end + 1, &end, 10);
        n_rows++;
    }
    fclose(f);
    if (n_rows < 2) die("the recording has fewer than two samples");
    rec_gap_s = rows[1].t_s - rows[0].t_s;
    rec_span_s = rows[n_rows - 1].t_s - rows[0].t_s + rec_gap_s;
}

/* The recording's row due at chip time t (it loops). */
static const row_t *row_at(double t) {
    double u = fmod(t, rec_span_s) + rows[0].t_s;
    size_t lo = 0, hi = n_rows - 1;
    while (lo < hi) {
        size_t mid = (lo + hi + 1) / 2;
        if (rows[mid].t_s <= u) lo = mid;
        else hi = mid - 1;
    }
    return &rows[lo];
}

/* ---- options and state ------------------------------------------------------------ */
static avr_t *avr;
static double opt_seconds = -1, opt_imu_off_at = -1, opt_noise_mv = 2.0, opt_speed = 1.0;
static int opt_no_imu, trace_i2c;
static int pinned[N_CH];
static double pinned_counts[N_CH];
static FILE *timing;
static int pty_master = -1;
static volatile sig_atomic_t stop_requested, imu_pulled;

static double chip_s(void) { return (double)avr->cycle / F_CPU; }
static double mono_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---- analog inputs: the value at each conversion, with noise ---------------------- */
static uint32_t rng = 12345u;
static double gauss(void) { /* Box-Muller on a xorshift generator */
    double u[2];
    for (int i = 0; i < 2; i++) {
        rng ^= rng << 13;
        rng ^= rng >> 17;
        rng ^= rng << 5;
        u[i] = (rng + 1.0) / 4294967297.0;
    }
    return sqrt(-2 * log(u[0])) * cos(2 * M_PI * u[1]);
}

static void burst_conversion(void);

static void adc_trigger(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    burst_conversion();
    unsigned src = (value >> 19) & 0x1FFF; /* avr_adc_mux_t: kind:3 gain:8 diff:8 src:13 */
    const row_t *r = row_at(chip_s());
    for (int k = 0; k < N_CH; k++) {
        if ((unsigned)adc_input[k] != src || (value & 7) != ADC_MUX_SINGLE) continue;
        double counts = pinned[k] ? pinned_counts[k] : r->raw[k];
        double mv = counts * 5000.0 / 4096.0 + opt_noise_mv * gauss();
        if (mv < 0) mv = 0;
        if (mv > 5000) mv = 5000;
        avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + adc_input[k]),
                      (uint32_t)lround(mv));
    }
}

/* ---- the button, from the recording ----------------------------------------------- */
static avr_cycle_count_t button_timer(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)param;
    const row_t *r = row_at(chip_s());
    avr_raise_irq(avr_io_getirq(a, AVR_IOCTL_IOPORT_GETIRQ('D'), 2), (r->buttons & 1) ? 0 : 1);
    return when + avr_usec_to_cycles(a, 1000);
}

/* ---- a BNO055 on I2C -------------------------------------------------------------- */
#define BNO_ADDR 0x28
static uint8_t bno[0x80];
static int bno_selected, bno_index, bno_reg;
static double bno_ndof_since = -1;
static avr_irq_t *bno_irq;

static void twi_status(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    if (trace_i2c) fprintf(stderr, "i2c %.6f status %02x\n", chip_s(), value);
}

static int bno_present(void) {
    if (opt_no_imu || imu_pulled) return 0;
    return !(opt_imu_off_at >= 0 && chip_s() >= opt_imu_off_at);
}

static avr_cycle_count_t bno_fusion(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)param;
    int16_t q[4] = {0, 0, 0, 0}; /* w x y z */
    const row_t *r = row_at(chip_s());
    if (bno[0x3D] == 0x0C && bno_ndof_since >= 0 && chip_s() - bno_ndof_since >= 0.007 &&
        !isnan(r->q[0])) {
        q[0] = (int16_t)lround(r->q[3] * 16384);
        for (int k = 0; k < 3; k++) q[k + 1] = (int16_t)lround(r->q[k] * 16384);
    }
    for (int k = 0; k < 4; k++) {
        bno[0x20 + 2 * k] = (uint8_t)(q[k] & 0xFF);
        bno[0x21 + 2 * k] = (uint8_t)((uint16_t)q[k] >> 8);
    }
    return when + avr_usec_to_cycles(a, 10000); /* NDOF fusion output: 100 Hz */
}

static void bno_twi(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    avr_twi_msg_irq_t v;
    v.u.v = value;
    if (trace_i2c)
        fprintf(stderr, "i2c %.6f msg %02x addr %02x data %02x\n", chip_s(), v.u.twi.msg, v.u.twi.addr, v.u.twi.data);
    if (v.u.twi.msg & TWI_COND_STOP) bno_selected = 0;
    if (v.u.twi.msg & TWI_COND_START) {
        bno_selected = 0;
        bno_index = 0;
        if ((v.u.twi.addr >> 1) == BNO_ADDR && bno_present()) {
            bno_selected = v.u.twi.addr;
            avr_raise_irq(bno_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, bno_selected, 1));
        }
    }
    if (!bno_selected) return;
    if (v.u.twi.msg & TWI_COND_WRITE) {
        avr_raise_irq(bno_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, bno_selected, 1));
        if (bno_index++ == 0) {
            bno_reg = v.u.twi.data & 0x7F;
        } else {
            if (bno_reg == 0x3D) {
                bno_ndof_since = (v.u.twi.data == 0x0C) ? chip_s() : -1;
            }
            bno[bno_reg] = v.u.twi.data;
            bno_reg = (bno_reg + 1) & 0x7F;
        }
    }
    if (v.u.twi.msg & TWI_COND_READ) {
        avr_raise_irq(bno_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_READ, bno_selected, bno[bno_reg]));
        bno_reg = (bno_reg + 1) & 0x7F;
    }
}

/* ---- UART to the pty, and the timing of each frame -------------------------------- */
static avr_cycle_count_t busy_cycles, counted_cycles;
/* Ticks whose frame has not ended yet, oldest first: at a slow baud a frame is still on
 * the wire when the next tick comes. */
#define TICKS_KEPT 8
static struct {
    avr_cycle_count_t cycle;
    double mono, chip;
    /* the ADC burst: conversions started while the test point is high */
    avr_cycle_count_t conv_first, conv_last;
    double conv_sum; /* of start cycles minus `cycle`, for the mean */
    unsigned conv_n;
    unsigned early_bytes; /* frame bytes out before the latest conversion started */
} ticks[TICKS_KEPT];
static unsigned ticks_head, ticks_n;
static uint32_t test_point_high;
static unsigned frame_bytes; /* bytes of the frame now going out */
static avr_cycle_count_t micros_origin; /* the Arduino core's init() starts timer 0 */
static int micros_started;
static unsigned long frames_out, bytes_dropped;
static unsigned long lat_n;
static double lat_sum_us, lat_max_us, lat_min_us = 1e9;
static double mid_sum_us, mid_max_us, mid_min_us = 1e9, span_sum_us;
#define WARMUP_S 1.0 /* the IMU starting up is not the steady state */

static double byte_time_us(void) {
    uint8_t ubrr_l = avr->data[0xC4], ubrr_h = avr->data[0xC5], ucsra = avr->data[0xC0];
    unsigned ubrr = ((unsigned)(ubrr_h & 0x0F) << 8) | ubrr_l;
    double baud = (double)F_CPU / ((ucsra & 0x02 ? 8.0 : 16.0) * (ubrr + 1));
    return 10.0 / baud * 1e6; /* start, 8 data, stop */
}

static void test_point(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    static uint32_t last;
    if (value && !last) {
        if (ticks_n == TICKS_KEPT) { /* frames never came: forget the oldest */
            ticks_head = (ticks_head + 1) % TICKS_KEPT;
            ticks_n--;
        }
        unsigned k = (ticks_head + ticks_n++) % TICKS_KEPT;
        ticks[k].cycle = avr->cycle;
        ticks[k].chip = chip_s();
        ticks[k].mono = mono_s();
        ticks[k].conv_n = 0;
        ticks[k].conv_sum = 0;
        ticks[k].early_bytes = 0;
    }
    last = value;
    test_point_high = value;
}

/* UCSR0B written: when the transmitter is enabled again, its data register is empty
 * (UDRE0 set), as on the chip. simavr 1.6 clears UDRE0 when TXEN0 falls (the Arduino
 * core's init() writes UCSR0B = 0) and sets it again only after a byte has gone out, so a
 * firmware that polls UDRE0 before its first byte (board_uart_send) would wait forever.
 * Runs after simavr's own handler for the register. */
static void uart_control_written(struct avr_t *a, avr_io_addr_t addr, uint8_t v, void *param) {
    (void)addr;
    (void)param;
    static uint8_t txen = 1; /* simavr's reset leaves the transmitter on */
    uint8_t now = (v >> 3) & 1; /* TXEN0 */
    if (now && !txen) a->data[0xC0] |= 1u << 5; /* UCSR0A's UDRE0 */
    txen = now;
}

/* TCCR0B written: the first non-zero write starts timer 0, micros()'s clock. */
static void timer0_started(struct avr_t *a, avr_io_addr_t addr, uint8_t v, void *param) {
    (void)addr;
    (void)param;
    if (v && !micros_started) {
        micros_started = 1;
        micros_origin = a->cycle;
    }
}

/* A conversion starts: it belongs to the newest tick's burst while the test point is high. */
static void burst_conversion(void) {
    if (!test_point_high || !ticks_n) return;
    unsigned k = (ticks_head + ticks_n - 1) % TICKS_KEPT;
    if (!ticks[k].conv_n) ticks[k].conv_first = avr->cycle;
    ticks[k].conv_last = avr->cycle;
    ticks[k].early_bytes = frame_bytes;
    ticks[k].conv_sum += (double)(avr->cycle - ticks[k].cycle);
    ticks[k].conv_n++;
}

static uint8_t out_buf[64];
static size_t out_len;
static int opt_whole_frames;

static void pty_write(const uint8_t *p, size_t n) {
    ssize_t w = write(pty_master, p, n);
    if (w < 0) w = 0;
    bytes_dropped += n - (size_t)w;
}

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    uint8_t b = (uint8_t)value;
    if (!opt_whole_frames) {
        pty_write(&b, 1);
    } else {
        out_buf[out_len++] = b;
        if (b == 0 || out_len == sizeof out_buf) {
            pty_write(out_buf, out_len);
            out_len = 0;
        }
    }
    frame_bytes = b ? frame_bytes + 1 : 0;
    if (b != 0 || !ticks_n) return; /* not a delimiter, or the one sent at reset */
    unsigned h = ticks_head;
    avr_cycle_count_t tick_cycle = ticks[h].cycle;
    double tick_mono = ticks[h].mono, tick_chip = ticks[h].chip;
    /* no conversion seen (a firmware that does not mark its burst): the tick stands in */
    double mid_cycle = (double)tick_cycle + (ticks[h].conv_n ? ticks[h].conv_sum / ticks[h].conv_n : 0.0);
    double span_us = ticks[h].conv_n ? (double)(ticks[h].conv_last - ticks[h].conv_first) * 1e6 / F_CPU : 0.0;
    unsigned conv_n = ticks[h].conv_n, early = conv_n ? ticks[h].early_bytes : 0;
    ticks_head = (ticks_head + 1) % TICKS_KEPT;
    ticks_n--;
    double us = (double)(avr->cycle - tick_cycle) * 1e6 / F_CPU + byte_time_us();
    double mid_us = ((double)avr->cycle - mid_cycle) * 1e6 / F_CPU + byte_time_us();
    frames_out++;
    if (chip_s() >= WARMUP_S) {
        lat_n++;
        lat_sum_us += us;
        if (us > lat_max_us) lat_max_us = us;
        if (us < lat_min_us) lat_min_us = us;
        mid_sum_us += mid_us;
        if (mid_us > mid_max_us) mid_max_us = mid_us;
        if (mid_us < mid_min_us) mid_min_us = mid_us;
        span_sum_us += span_us;
    }
    if (timing)
        fprintf(timing, "%lu %.7f %.7f %.1f %.7f %.1f %.7f %.1f %u %.1f %u\n", frames_out, tick_mono,
                mono_s() + byte_time_us() * 1e-6, us, tick_chip, mid_us, mid_cycle / F_CPU,
                span_us, conv_n, (mid_cycle - (double)micros_origin) * 1e6 / F_CPU, early);
}

static void on_signal(int sig) {
    if (sig == SIGUSR1) imu_pulled = 1;
    else stop_requested = 1;
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long) {
    (void)a;
    (void)how_long; /* the main loop paces to wall time */
}

static void open_pty(void) {
    pty_master = posix_openpt(O_RDWR | O_NOCTTY);
    if (pty_master < 0 || grantpt(pty_master) || unlockpt(pty_master)) die("cannot open a pty");
    const char *name = ptsname(pty_master);
    int slave = open(name, O_RDWR | O_NOCTTY); /* kept open: writes never fail for want of a reader */
    if (slave < 0) die("cannot open the pty's slave side");
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(pty_master, F_SETFL, fcntl(pty_master, F_GETFL) | O_NONBLOCK);
    printf("port: %s\n", name);
    fflush(stdout);
}

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: avr_glove FIRMWARE.elf RECORDING.csv [--seconds S] [--no-imu] "
                        "[--imu-off-at S] [--pin CH=COUNTS] [--timing FILE] [--noise MV] [--speed X]\n");
        return 2;
    }
    for (int i = 3; i < argc; i++) {
        const char *a = argv[i];
        const char *val = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--no-imu")) opt_no_imu = 1;
        else if (!strcmp(a, "--whole-frames")) opt_whole_frames = 1;
        else if (!strcmp(a, "--seconds") && val) opt_seconds = atof(argv[++i]);
        else if (!strcmp(a, "--imu-off-at") && val) opt_imu_off_at = atof(argv[++i]);
        else if (!strcmp(a, "--noise") && val) opt_noise_mv = atof(argv[++i]);
        else if (!strcmp(a, "--speed") && val) opt_speed = atof(argv[++i]);
        else if (!strcmp(a, "--timing") && val) {
            timing = fopen(argv[++i], "w");
            if (!timing) die("cannot write the --timing file");
            setvbuf(timing, NULL, _IOLBF, 0); /* written as it happens */
        } else if (!strcmp(a, "--pin") && val) {
            int ch;
            double counts;
            if (sscanf(argv[++i], "%d=%lf", &ch, &counts) != 2 || ch < 0 || ch >= N_CH)
                die("--pin wants CH=COUNTS with CH 0..4");
            pinned[ch] = 1;
            pinned_counts[ch] = counts;
        } else {
            fprintf(stderr, "avr_glove: unknown option %s\n", a);
            return 2;
        }
    }
    if (opt_speed <= 0) die("--speed must be positive");
    read_recording(argv[2]);
    trace_i2c = getenv("AVR_GLOVE_TRACE_I2C") != NULL;

    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[1], &fw) != 0) die("cannot read the firmware ELF (run 'make firmware')");
    strcpy(fw.mmcu, "atmega328p");
    fw.frequency = F_CPU;
    avr = avr_make_mcu_by_name(fw.mmcu);
    if (!avr) die("simavr has no atmega328p");
    avr_init(avr);
    avr->log = LOG_ERROR;
    avr_load_firmware(avr, &fw);
    avr->frequency = F_CPU;
    avr->vcc = avr->avcc = avr->aref = 5000;
    avr->sleep = no_sleep;

    uint32_t uart_flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &uart_flags);
    uart_flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &uart_flags);
    open_pty();
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_OUT_TRIGGER), adc_trigger, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 0), test_point, NULL);
    avr_register_io_write(avr, 0x45 /* TCCR0B */, timer0_started, NULL); /* beside the timer's own */
    avr_register_io_write(avr, 0xC1 /* UCSR0B */, uart_control_written, NULL); /* after the UART's */

    static const char *twi_names[2] = {"8>bno055.out", "32<bno055.in"};
    bno_irq = avr_alloc_irq(&avr->irq_pool, 0, 2, twi_names);
    avr_irq_register_notify(bno_irq + TWI_IRQ_OUTPUT, bno_twi, NULL);
    avr_connect_irq(bno_irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
    avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), bno_irq + TWI_IRQ_OUTPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_STATUS), twi_status, NULL);
    bno[0x00] = 0xA0; /* CHIP_ID */
    bno[0x35] = 0xFF; /* CALIB_STAT: system, gyro, accel, mag all 3 */
    avr_cycle_timer_register_usec(avr, 1000, bno_fusion, NULL);
    avr_cycle_timer_register_usec(avr, 100, button_timer, NULL);

    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    signal(SIGUSR1, on_signal);
    signal(SIGPIPE, SIG_IGN);
    double wall0 = mono_s();
    avr_cycle_count_t next_pace = 0, pace_step = F_CPU / 10000; /* every 100 us of chip time */
    int state = cpu_Running;
    while (!stop_requested && state != cpu_Done && state != cpu_Crashed) {
        int sleeping = avr->state == cpu_Sleeping;
        avr_cycle_count_t c0 = avr->cycle;
        state = avr_run(avr);
        if (chip_s() >= WARMUP_S) {
            counted_cycles += avr->cycle - c0;
            if (!sleeping) busy_cycles += avr->cycle - c0;
        }
        if (avr->cycle < next_pace) continue;
        next_pace = avr->cycle + pace_step;
        double ahead = chip_s() / opt_speed - (mono_s() - wall0);
        if (ahead > 200e-6) {
            struct timespec ts = {0, (long)(ahead * 1e9)};
            nanosleep(&ts, NULL);
        }
        if (opt_seconds >= 0 && chip_s() >= opt_seconds) break;
    }
    double behind = (mono_s() - wall0) - chip_s() / opt_speed;
    if (!lat_n) lat_min_us = mid_min_us = 0; /* nothing measured after the warm-up */
    printf("figures: chip_s %.3f frames %lu sample_to_last_byte_us mean %.1f min %.1f max %.1f "
           "burst_middle_to_last_byte_us mean %.1f min %.1f max %.1f burst_span_us %.1f "
           "cpu_busy %.4f behind_wall_s %.3f bytes_dropped %lu state %d\n",
           chip_s(), frames_out, lat_n ? lat_sum_us / lat_n : 0.0,
           lat_min_us, lat_max_us, lat_n ? mid_sum_us / lat_n : 0.0, mid_min_us, mid_max_us,
           lat_n ? span_sum_us / lat_n : 0.0,
           counted_cycles ? (double)busy_cycles / counted_cycles : 0.0, behind, bytes_dropped, state);
    if (timing) fclose(timing);
    return state == cpu_Crashed ? 1 : 0;
}
