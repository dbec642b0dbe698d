/* Reset for the C example on the STM32F405 under QEMU: vector table, FPU on, .data copied and
 * .bss zeroed, the stack painted for its high-water mark, newlib's semihosting I/O set up, then
 * main; its return value is the semihosting exit status. */

#include <stdint.h>
#include <stdlib.h>

extern uint32_t _data_load, _data_start, _data_end, _bss_start, _bss_end, _stack_bottom, _stack_top;
extern int main(void);
extern void initialise_monitor_handles(void);

#define STACK_PAINT 0xCAFEF00Du

void reset_handler(void);

static void fault_handler(void) {
    exit(99);
}

/* Initial stack pointer, reset, NMI, hard fault, memory, bus and usage faults. */
__attribute__((section(".isr_vector"), used)) static void (*const vector_table[7])(void) = {
    (void (*)(void))(&_stack_top), reset_handler, fault_handler, fault_handler,
    fault_handler, fault_handler, fault_handler,
};

/* The bytes of the stack not yet used, counted from the bottom. */
uint32_t stack_unused_bytes(void) {
    const uint32_t *word = &_stack_bottom;
    while (word < &_stack_top && *word == STACK_PAINT) {
        word++;
    }
    return (uint32_t)((uintptr_t)word - (uintptr_t)&_stack_bottom);
}

uint32_t stack_size_bytes(void) {
    return (uint32_t)((uintptr_t)&_stack_top - (uintptr_t)&_stack_bottom);
}

void reset_handler(void) {
    /* CP10 and CP11 full access: the library is built for the hard-float ABI. */
    volatile uint32_t *const cpacr = (uint32_t *)0xE000ED88u;
    *cpacr |= 0xFu << 20;
    __asm volatile("dsb\n isb" ::: "memory");
    for (uint32_t *src = &_data_load, *dst = &_data_start; dst < &_data_end;) {
        *dst++ = *src++;
    }
    for (uint32_t *dst = &_bss_start; dst < &_bss_end;) {
        *dst++ = 0;
    }
    /* Paint the stack below this frame (a generous 256 bytes below the present pointer). */
    uint32_t *sp;
    __asm volatile("mov %0, sp" : "=r"(sp));
    for (uint32_t *word = &_stack_bottom; word < sp - 64;) {
        *word++ = STACK_PAINT;
    }
    initialise_monitor_handles();
    exit(main());
}

/* newlib's exit runs the .fini hooks; crti.o (left out with -nostartfiles) would define these. */
void _init(void) {}
void _fini(void) {}
