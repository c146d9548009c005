/* Runs an identifier exported by pyrhonn.export over a test vector and
 * prints every prediction as a C99 hex float, one sample per line. Compiled
 * by tests/test_export.py with the exported header and a generated vector:
 *   exported.h  defines  static const rhonn_config EXPORTED;
 *   vector.h    defines  VEC_T, VEC_N, VEC_M, vec_x[], vec_u[], vec_valid[]
 * With EXPORT_WARM defined, exported.h also defines EXPORTED_warm (a
 * rhonn_warm_state) and the identifier starts with rhonn_warm_start.
 * Compiles as C99 and as C++.
 */
#include <stdio.h>

#include "exported.h"
#include "vector.h"

int main(void)
{
    static rhonn_t net;
    static rhonn_real out[VEC_T * VEC_N];
    rhonn_config_error where;
    size_t done = 0, k, j;
#ifdef EXPORT_WARM
    rhonn_status st = rhonn_warm_start(&net, &EXPORTED, &EXPORTED_warm, &where);
#else
    rhonn_status st = rhonn_init(&net, &EXPORTED, &where);
#endif

    if (st != RHONN_OK) {
        fprintf(stderr, "start: %s (field %u neuron %u)\n", rhonn_status_name(st), where.field, where.neuron);
        return 2;
    }
    st = rhonn_run(&net, VEC_T, vec_x, vec_u, vec_valid, out, &done);
    if (st != RHONN_OK) {
        fprintf(stderr, "rhonn_run: %s after %u steps\n", rhonn_status_name(st), (unsigned)done);
        return 3;
    }
    for (k = 0; k < VEC_T; ++k) {
        for (j = 0; j < VEC_N; ++j) {
            printf(j ? " %a" : "%a", (double)out[k * VEC_N + j]);
        }
        printf("\n");
    }
    return 0;
}
