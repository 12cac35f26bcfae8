#!/usr/bin/env bash
# Regenerates the README's gallery (docs/gallery/*.webp): three short looping animations made
# with makeit4d's own commands, encoded as animated WebP by ffmpeg (libwebp). Needs ffmpeg on
# PATH. Uses ../shared/data/photos/cold_ripple.jpg when present, else the 320-px copy in
# tests/data.
#
#   scripts/gallery.sh            # builds makeit4d (release) first
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked --quiet
bin=target/release/makeit4d
out=docs/gallery
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cold=../shared/data/photos/cold_ripple.jpg
[ -f "$cold" ] || cold=tests/data/cold_ripple_320.jpg
mkdir -p "$out"
start=$(date +%s)
# 1. The sample's fly-in (the default path).
"$bin" render assets/evening_glow.jpg --frames 48 --size 480x300 --out "$tmp/fly-in"
# 2. An orbit with the automatic motion: clouds drift, the lake flows (an 80-frame loop).
"$bin" render assets/evening_glow.jpg --preset orbit --motion auto --frames 80 --size 480x300 \
    --out "$tmp/orbit"
# 3. A fly-out of the misty pier: the canvas outpainted around the photo.
"$bin" render "$cold" --preset fly-out --frames 48 --size 480x300 --out "$tmp/fly-out"
for name in fly-in orbit fly-out; do
    ffmpeg -loglevel error -y -framerate 24 -i "$tmp/$name/frame_%04d.png" \
        -c:v libwebp_anim -lossless 0 -quality 75 -compression_level 6 -loop 0 \
        "$tmp/$name.webp"
    mv "$tmp/$name.webp" "$out/$name.webp"
done
ls -l "$out"
echo "gallery: $(( $(date +%s) - start )) s"
