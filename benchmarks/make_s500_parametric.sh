#!/usr/bin/env sh
# Regenerate calibrations/s500_parametric.json: the S500-like virtual machine's axis error
# tables measured by a simulated laser interferometer (2 mm step, instrument noise, fixed
# seed), then fitted as the 21-parameter model.
set -eu
cd "$(dirname "$0")/.."
postproc simulate calibrations/s500.machine.json --tables --step 2 --seed 1 \
    -o samples/s500_interferometer_2mm.csv
postproc fit samples/s500_interferometer_2mm.csv --name s500_parametric \
    -o calibrations/s500_parametric.json
