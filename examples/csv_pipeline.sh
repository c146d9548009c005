#!/usr/bin/env bash
# The command line on your own CSV: select the terms and delays, validate the
# model on samples it never fitted, export it for firmware.
#
#   bash examples/csv_pipeline.sh [FOLDER]      (default: a new temporary folder)
#
# The recording here comes from a small plant whose input acts after a dead
# time (y(k+1) reads u(k-2): select reports 2 samples) and a 20-sample sensor
# dropout (y_valid = 0); put your own CSV in
# its place: a header naming the columns, one line per sample.
set -euo pipefail
out=${1:-$(mktemp -d)}
mkdir -p "$out" && cd "$out"

python3 - <<'PY'
import numpy as np
rng = np.random.default_rng(3)
T = 1500
u = np.repeat(rng.uniform(-1, 1, T // 30 + 1), 30)[:T]
y = np.zeros(T)
for k in range(3, T):
    y[k] = 0.8 * y[k - 1] + 0.3 * np.tanh(1.5 * u[k - 3])   # y(k+1) from u(k-2)
y += 0.002 * rng.standard_normal(T)
valid = np.ones(T, dtype=int)
valid[900:920] = 0
cells = [f"{0.01 * k:.2f},{'' if not valid[k] else f'{y[k]:.6f}'},{u[k]:.6f},{valid[k]}" for k in range(T)]
open("run.csv", "w").write("t,y,u,y_valid\n" + "\n".join(cells) + "\n")
PY

# terms and delays from the first 1,000 samples; the rest ranks the candidates
pyrhonn select run.csv --states y --inputs u --fit-rows 0:1000 --validate-rest --out model.toml \
    --report select.txt > /dev/null
grep -m1 "input dead time: u 2 sample" select.txt   # fails the script if not found
# frozen weights on every sample: exit 1 if the free run's fit is below 90 %
pyrhonn validate run.csv --config model.toml --out validation --min-fit 90 --no-plots | grep -A1 "^verdict"
# learn online over the recording, then write the trained identifier as a C header
# (in the config's float64; examples/firmware.sh builds a float32 one into C)
pyrhonn export --config model.toml --data run.csv --out model.h
echo "outputs in $out: model.toml, validation/, model.h, model_capacity.h"
