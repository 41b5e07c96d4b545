#!/usr/bin/env sh
# Regenerate calibrations/s500_static.json from a simulated six-point tracker run on the
# S500-like virtual machine (two points per axis, 12 shots each, as in seed 000).
set -eu
cd "$(dirname "$0")/.."
postproc simulate calibrations/s500.machine.json --static-set --repeats 12 --seed 0 \
    -o samples/s500_static_6points.csv
postproc fit samples/s500_static_6points.csv --method static --name s500_static \
    -o calibrations/s500_static.json
