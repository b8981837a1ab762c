#!/bin/sh
# Scores of a weights bundle on the real sets (the Ottawa crops imported to /tmp/ottawa, see
# docs/real-imagery.md; the dense-urban NYC patch read from ../shared/data/real) and on the
# synthetic test cities of every style (CITIES="..." names fewer). Usage: scripts/eval_bundle.sh BUNDLE TAG (OUT=folder)
set -e
cd "$(dirname "$0")/.."
mkdir -p "${OUT:-runs/eval}"
cs=".venv/bin/csboundary"
B=$1; T=$2; O=${OUT:-runs/eval}
N=${NYC:-../shared/data/real/nyc-topo-boundary}
$cs predict $N/000180_31_image.tif --weights $B --out $O/$T-nyc --quiet > $O/$T-nyc-predict.txt 2>&1
$cs evaluate $O/$T-nyc/boundaries.gpkg $N/000180_31_gt.geojson --raster $N/000180_31_image.tif --scale patch --json $O/$T-nyc.json > $O/$T-nyc.txt 2>&1
$cs evaluate-set /tmp/ottawa --weights $B --json $O/$T-ottawa.json --quiet > $O/$T-ottawa.txt 2>&1
ALL="test-s7-2x2-2000 test-s8-2x2-2000 test-grid-s7-2x2-2000 test-downtown-s7-2x2-2000 test-dense-s7-2x2-2000 test-suburb-s7-2x2-2000 test-rural-s7-2x2-2000 test-irregular-s7-2x2-2000 test-residential-s7-2x2-2000 test-leafy-s7-2x2-2000 test-highway-s7-2x2-2000"
for c in ${CITIES:-$ALL}; do
  $cs evaluate-model data/cities/$c --weights $B --json $O/$T-$c.json --quiet > $O/$T-$c.txt 2>&1
done
echo done
