/* The roll-moment estimator flown from C: replays a run under QEMU (STM32F405) through the C
 * interface (roll_estimator.h, libroll_estimator.a), as the Rust firmware replays it, and writes
 * the same binary output format (firmware-sim/src/frames.rs) for `host-tools qemu-replay
 * --c-example` to compare with the host replay.
 *
 * Files (semihosting, in QEMU's working folder): firmware-in.bin (input), model.bin (optional:
 * a coefficient blob; without it the built-in tables fly), firmware-out.bin (output).
 * Exit status: 0; a rollest_status code (1..19) when the estimator refuses its storage or the
 * blob; 101..104 for a file that cannot be read or written; 105 when the library's version is
 * not this header's (rollest_version() != ROLLEST_VERSION), 106 when its struct sizes are not
 * (ROLLEST_ABI_OK() fails): a header and a library from different builds.
 *
 * Built by the Makefile beside it (`make LIB_DIR=... OUT_DIR=...`). */

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "roll_estimator.h"

uint32_t stack_unused_bytes(void);
uint32_t stack_size_bytes(void);

enum { HEADER_LEN = 16, INPUT_LEN = 64, OUTPUT_LEN = 80, TRAILER_WORDS = 13, FORMAT_VERSION = 1 };
enum { EXIT_INPUT = 101, EXIT_OUTPUT = 102, EXIT_MODEL = 103, EXIT_WRITE = 104 };
enum { EXIT_VERSION = 105, EXIT_ABI = 106 }; /* a header and a library from different builds */

/* SysTick, clocked by the core (168 MHz): counts down from its 24-bit reload. */
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
#define SYST_MASK 0xFFFFFFu
#define CORE_CLOCK_HZ 168000000u
#define CALIBRATION_LOOPS 200000u

static uint32_t ticks_between(uint32_t start, uint32_t end) {
    return (start - end) & SYST_MASK;
}

/* A counted loop of 2 instructions per iteration (subs, bne): ticks per instruction. */
static uint32_t calibration_ticks(void) {
    uint32_t loops = CALIBRATION_LOOPS;
    uint32_t start = SYST_CVR;
    __asm volatile("1: subs %0, %0, #1\n bne 1b" : "+r"(loops) : : "cc");
    return ticks_between(start, SYST_CVR);
}

static uint32_t word_at(const uint8_t *bytes, int index) {
    uint32_t value;
    memcpy(&value, bytes + 4 * index, 4);
    return value;
}

static void put_word(uint8_t *bytes, int index, uint32_t value) {
    memcpy(bytes + 4 * index, &value, 4);
}

static void put_float(uint8_t *bytes, int index, float value) {
    memcpy(bytes + 4 * index, &value, 4);
}

/* The estimator's storage: caller-owned, static, never moved. */
static rollest_estimator estimator;
static uint8_t blob[8192];

static int init_estimator(void) {
    FILE *model = fopen("model.bin", "rb");
    if (model == NULL) {
        return rollest_init_built_in(&estimator, sizeof estimator);
    }
    size_t len = fread(blob, 1, sizeof blob, model);
    int complete = feof(model) || fgetc(model) == EOF;
    fclose(model);
    if (!complete) {
        return EXIT_MODEL;
    }
    return rollest_init_blob(&estimator, sizeof estimator, blob, len);
}

int main(void) {
    /* Before any other call: the library linked in must be the one this header describes. */
    if (rollest_version() != ROLLEST_VERSION) {
        printf("library version %lu, header version %d\n", (unsigned long)rollest_version(), ROLLEST_VERSION);
        return EXIT_VERSION;
    }
    if (!ROLLEST_ABI_OK()) {
        printf("the library's struct sizes are not this header's\n");
        return EXIT_ABI;
    }

    SYST_RVR = SYST_MASK;
    SYST_CVR = 0;
    SYST_CSR = 0x5; /* enabled, core clock, no exception */
    uint32_t calibration = calibration_ticks();

    int status = init_estimator();
    if (status != ROLLEST_STATUS_OK) {
        printf("estimator refused: %s (%d)\n", rollest_status_text(status), status);
        return status;
    }

    FILE *input = fopen("firmware-in.bin", "rb");
    uint8_t header[HEADER_LEN];
    if (input == NULL || fread(header, 1, HEADER_LEN, input) != HEADER_LEN || memcmp(header, "RMEI", 4) != 0
        || word_at(header, 1) != FORMAT_VERSION || word_at(header, 3) != INPUT_LEN) {
        return EXIT_INPUT;
    }
    uint32_t n_samples = word_at(header, 2);
    FILE *output = fopen("firmware-out.bin", "wb");
    if (output == NULL) {
        return EXIT_OUTPUT;
    }
    memcpy(header, "RMEO", 4);
    put_word(header, 3, OUTPUT_LEN);
    if (fwrite(header, 1, HEADER_LEN, output) != HEADER_LEN) {
        return EXIT_WRITE;
    }

    uint64_t ticks_sum = 0;
    uint32_t ticks_max = 0, steps = 0;
    uint8_t record[INPUT_LEN > OUTPUT_LEN ? INPUT_LEN : OUTPUT_LEN];
    while (steps < n_samples && fread(record, 1, INPUT_LEN, input) == INPUT_LEN) {
        rollest_input in; /* the input record's 16 floats are the struct's fields, in order */
        memcpy(&in, record, sizeof in);
        rollest_output out;
        uint32_t start = SYST_CVR;
        status = rollest_step(&estimator, &in, &out);
        uint32_t ticks = ticks_between(start, SYST_CVR);
        if (status != ROLLEST_STATUS_OK) {
            return status;
        }
        const float estimates[10] = {out.cl_egk,  out.cl_pressure, out.cl_roll,   out.cl_afc_port, out.cl_afc_stbd,
                                     out.cl_afc,  out.cl_linear,   out.coupling,  out.cl,          out.phi_dot_rad_s};
        for (int i = 0; i < 10; i++) {
            put_float(record, i, estimates[i]);
        }
        put_word(record, 10, out.health.flags);
        put_word(record, 11, out.health.cp_missing);
        put_word(record, 12, out.health.cp_rejected);
        put_word(record, 13, out.health.cp_isolated);
        for (int i = 14; i < 18; i++) {
            put_word(record, i, 0); /* no controller in this example */
        }
        put_word(record, 18, ticks);
        put_word(record, 19, ticks);
        if (fwrite(record, 1, OUTPUT_LEN, output) != OUTPUT_LEN) {
            return EXIT_WRITE;
        }
        steps++;
        ticks_sum += ticks;
        ticks_max = ticks > ticks_max ? ticks : ticks_max;
    }

    uint8_t trailer[4 + 4 * TRAILER_WORDS];
    memcpy(trailer, "RMET", 4);
    const uint32_t words[TRAILER_WORDS] = {
        steps, (uint32_t)ticks_sum, (uint32_t)(ticks_sum >> 32), ticks_max,
        (uint32_t)ticks_sum, (uint32_t)(ticks_sum >> 32), ticks_max,
        2u * CALIBRATION_LOOPS, calibration, CORE_CLOCK_HZ,
        stack_size_bytes() - stack_unused_bytes(), stack_size_bytes(), 0,
    };
    for (int i = 0; i < TRAILER_WORDS; i++) {
        put_word(trailer + 4, i, words[i]);
    }
    if (fwrite(trailer, 1, sizeof trailer, output) != sizeof trailer || fclose(output) != 0) {
        return EXIT_WRITE;
    }
    fclose(input);
    return 0;
}
