#!/bin/sh
# The real-cut procedure on case 1022 (README.md here). Run from the repository
# root; the shared data is ../shared unless SERVOSURF_SHARED says otherwise.
#
#   sh examples/real_cut/run_1022.sh [OUT]        (default OUT: results/1022)
set -e
SHARED=${SERVOSURF_SHARED:-../shared}
CASE=$SHARED/data/upm_sts/1022
OUT=${1:-results/1022}

# 1. The predicted surface: the program's blocks swept by the tool, kinematics
#    only, on a band through the spindle axis across the whole radius.
servosurf simulate "$CASE/1022-spiralPath20230418T214917.nc" \
    --block-time 1e-3 --tool-radius 189.36e-6 --out "$OUT"

# 2. Against the white-light profile through the centre.
servosurf compare "$CASE/1022-WLI-2D.csv" --simulated "$OUT/surface.datx" \
    --cutoff 2.5e-4 --out "$OUT-wli"

# 3. Against the Formtracer contour, cropped to the cut zone (the rim of the
#    1 mm aperture; outside it the contour holds the part's flanks).
servosurf compare "$CASE/1022-contour.DAT" --simulated "$OUT/surface.datx" \
    --x-range -0.00099 0.00099 --cutoff 2.5e-4 --labels Formtracer simulated \
    --out "$OUT-formtracer"
