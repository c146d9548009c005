#!/usr/bin/env bash
# A trained identifier into firmware: export it from Python as a C header,
# compile it with the C core and step it over a recording in C.
#
#   bash examples/firmware.sh [FOLDER]      (default: a new temporary folder)
#
# Run from anywhere inside a clone of pyrhonn (it compiles csrc/src/rhonn.c).
# The C program (examples/firmware_main.c) exits 1 if its predictions are off.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
core=$(cd "$here/../csrc" && pwd)
out=${1:-$(mktemp -d)}
mkdir -p "$out" && cd "$out"

# the shipped firmware-lim identifier over 1 s of the simulated linear induction motor
pyrhonn hil trajectory --duration 1.0 --input-start 0.2 lim.csv > /dev/null
pyrhonn export --config firmware-lim --data lim.csv --fit-rows 0:2000 --out lim_id.h --name lim_id
cc -std=c99 -O2 -ffp-contract=off -DRHONN_SINGLE -DRHONN_USER_CAPACITY='"lim_id_capacity.h"' \
   -I"$core/include" -I. "$here/firmware_main.c" "$core/src/rhonn.c" -o firmware_main -lm
./firmware_main lim.csv 2000
