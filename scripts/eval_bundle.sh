#!/bin/sh
# Scores of a weights bundle on the Ottawa crops (imported to /tmp/ottawa, see docs/real-imagery.md)
# and on the synthetic test cities of every style. Usage: scripts/eval_bundle.sh BUNDLE TAG (OUT=folder)
set -e
cd "$(dirname "$0")/.."
mkdir -p "${OUT:-runs/eval}"
cs=".venv/bin/csboundary"
B=$1; T=$2
$cs evaluate-set /tmp/ottawa --weights $B --json ${OUT:-runs/eval}/$T-ottawa.json --quiet > ${OUT:-runs/eval}/$T-ottawa.txt 2>&1
for c in test-s7-2x2-2000 test-s8-2x2-2000 test-grid-s7-2x2-2000 test-downtown-s7-2x2-2000 test-suburb-s7-2x2-2000 test-rural-s7-2x2-2000 test-irregular-s7-2x2-2000 test-residential-s7-2x2-2000 test-leafy-s7-2x2-2000 test-highway-s7-2x2-2000; do
  $cs evaluate-model data/cities/$c --weights $B --json ${OUT:-runs/eval}/$T-$c.json --quiet > ${OUT:-runs/eval}/$T-$c.txt 2>&1
done
echo done
