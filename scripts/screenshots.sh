#!/usr/bin/env bash
# Screenshots of every tab of the studio after a real run, at 1280x720 and 1920x1080, on a virtual display:
#   bash scripts/screenshots.sh [OUT]   (default: resources/screenshots; about six minutes on two cores)
# Writes OUT/<width>x<height>/{pair,texture,product,sequence,retrieval,compare}.png.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-resources/screenshots}"
export QT_QPA_PLATFORM=xcb
studio=.venv/bin/corr-studio
collection="$(mktemp -d)"
trap 'rm -rf "$collection"' EXIT
.venv/bin/python -c "import sys; from corrlib.resources import retrieval_collection; retrieval_collection(sys.argv[1])" \
    "$collection/people-and-animals"
query=resources/data/sketch2d/human_sketch_a_contour.txt
for size in 1280x720 1920x1080; do
    mkdir -p "$OUT/$size"
    shot() { xvfb-run -a -s "-screen 0 ${size}x24" "$studio" "$@" --timeout 900; }
    shot --demo --method fmap-zoomout --screenshot "$OUT/$size/pair.png"
    shot --demo --method fmap-zoomout --pair-mode texture --screenshot "$OUT/$size/texture.png"
    shot "$query" resources/people/human1.off --method contour3d --screenshot "$OUT/$size/product.png"
    shot --demo --method fmap-zoomout --tab Sequence --sequence-t 0.5 --screenshot "$OUT/$size/sequence.png"
    shot "$query" --retrieve "$collection/people-and-animals" --screenshot "$OUT/$size/retrieval.png"
    shot --demo --compare --screenshot "$OUT/$size/compare.png"
done
echo "screenshots: wrote $OUT/1280x720 and $OUT/1920x1080"
