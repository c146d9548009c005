/* Steps an identifier exported by pyrhonn over a CSV recording, as firmware
 * would in its control interrupt, and prints its one-step error per state.
 *
 *   firmware_main DATA.csv FIRST
 *
 * DATA.csv: a header, then one line per sample: t, the n states, the m inputs
 * (the layout `pyrhonn hil trajectory` writes). Samples from line FIRST on are
 * stepped (the export trained on the ones before). Exit 1 if a step fails or
 * the error of a state exceeds 5 % of its RMS value. Built by examples/firmware.sh
 * with the exported lim_id.h and its capacity header. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rhonn.h"
#include "lim_id.h"

static rhonn_t net; /* all of the identifier's state: no allocation anywhere */

int main(int argc, char **argv)
{
    enum { N = RHONN_MAX_STATES, M = RHONN_MAX_INPUTS };
    char line[4096];
    rhonn_real x[N], u[M], xhat[N], pred[N];
    double sq[N] = {0}, sum2[N] = {0};
    long first, row = 0, scored = 0;
    size_t n = lim_id.n_states, m = lim_id.n_inputs, i;
    int have_pred = 0;
    rhonn_status st;
    FILE *f;

    if (argc != 3 || (f = fopen(argv[1], "r")) == NULL) {
        fprintf(stderr, "usage: %s DATA.csv FIRST\n", argv[0]);
        return 2;
    }
    first = strtol(argv[2], NULL, 10);
    if (rhonn_init(&net, &lim_id, NULL) != RHONN_OK || fgets(line, sizeof line, f) == NULL) {
        fprintf(stderr, "cannot start: bad configuration or empty file\n");
        return 1;
    }
    while (fgets(line, sizeof line, f) != NULL) {
        char *p = line;
        (void)strtod(p, &p); /* t */
        for (i = 0; i < n; i++) x[i] = (rhonn_real)strtod(p + 1, &p);
        for (i = 0; i < m; i++) u[i] = (rhonn_real)strtod(p + 1, &p);
        if (row++ < first) continue;
        if (have_pred) { /* score the prediction made at the previous sample */
            for (i = 0; i < n; i++) {
                double e = (double)x[i] - (double)pred[i];
                sq[i] += e * e;
                sum2[i] += (double)x[i] * (double)x[i];
            }
            scored++;
        }
        st = rhonn_step(&net, x, u, NULL, xhat);
        if (st != RHONN_OK) {
            fprintf(stderr, "step at line %ld refused: %s\n", row + 1, rhonn_status_name(st));
            return 1;
        }
        memcpy(pred, xhat, sizeof pred);
        have_pred = 1;
    }
    fclose(f);
    if (scored == 0) {
        fprintf(stderr, "no sample after line %ld\n", first);
        return 1;
    }
    {
        int ok = 1;
        printf("%ld samples stepped in C; one-step RMSE per state (and relative to its RMS value):\n", scored);
        for (i = 0; i < n; i++) {
            double rmse = sqrt(sq[i] / (double)scored);
            double rms = sqrt(sum2[i] / (double)scored);
            printf("  state %zu: %.4g (%.2f %%)\n", i + 1, rmse, 100.0 * rmse / rms);
            ok &= rmse <= 0.05 * rms;
        }
        printf("%s\n", ok ? "OK" : "NOT AS STATED");
        return ok ? 0 : 1;
    }
}
