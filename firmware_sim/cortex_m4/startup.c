/* Bare-metal entry for QEMU's mps2-an386 (Cortex-M4F): the vector table and
 * a reset handler that turns the FPU on, copies .data, and hands over to
 * newlib's rdimon crt0 (_start), which clears .bss, sets up semihosting
 * stdio and calls main(). Nothing here is specific to the identifier. */
#include <stdint.h>

extern void _start(void);
extern uint32_t __etext, __data_start__, __data_end__, __stack_top__;

void Reset_Handler(void);
void Default_Handler(void);

void Default_Handler(void)
{
    for (;;) {
    }
}

void Reset_Handler(void)
{
    volatile uint32_t *const cpacr = (volatile uint32_t *)0xE000ED88u;
    const uint32_t *src = &__etext;
    uint32_t *dst = &__data_start__;

    /* CP10 and CP11 full access: the FPU must be on before any float op. */
    *cpacr |= (0xFu << 20);
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    while (dst < &__data_end__) {
        *dst++ = *src++;
    }
    _start();
    for (;;) {
    }
}

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))(uintptr_t)&__stack_top__, /* initial SP */
    Reset_Handler,                               /* reset */
    Default_Handler, Default_Handler, Default_Handler, Default_Handler, Default_Handler, 0, 0, 0, 0,
    Default_Handler, Default_Handler, 0, Default_Handler, Default_Handler,
};
