#!/usr/bin/env bash
# Regenerate the README pictures of the 3-D viewer (off-screen; about a minute).
# Usage: docs/images/make_images.sh   (from the repository root, venv active)
set -euo pipefail
out="$(dirname "$0")"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# The thesis tank seen from above (like the seed's figure 3-8) and in perspective, with the
# traced paths and the time-of-flight ellipses of the echo from the first post.
acoustisim view thesis-tank --camera top --echo post-1 --png "$out/thesis-tank-top.png"
acoustisim view thesis-tank --camera perspective --png "$out/thesis-tank-perspective.png"
# A validation scene: the free-field cylinder, its specular and edge paths and the
# time-of-flight ellipsoids of its first echo.
acoustisim view free-cylinder --camera perspective --echo 0 --png "$out/free-cylinder-paths.png"
# A localisation result: simulate a ping of the thesis tank, localise, show every estimate
# (numbered, 2-sigma error ellipsoids magnified) against the truth.
acoustisim simulate thesis-tank -o "$tmp/ping.h5" --seed 1 >/dev/null
binsonar localize "$tmp/ping.h5" --json > "$tmp/results.json"
acoustisim view thesis-tank --ping "$tmp/ping.h5" --results "$tmp/results.json" --camera targets \
    --no-paths --no-beam --title "thesis-tank: binsonar localize estimates vs truth" \
    --png "$out/thesis-tank-localisation.png"
