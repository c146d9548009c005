/* Deliberately allocates and prints: the symbol check must reject this. */
#include <stdio.h>
#include <stdlib.h>

void *rhonn_canary(size_t n);
void *rhonn_canary(size_t n)
{
    void *p = malloc(n);
    printf("%p\n", p);
    return p;
}
