#!/usr/bin/env bash
# Renders packaging/makeit4d.svg to the PNG sizes the desktop entry installs
# (packaging/icons/NxN.png). Needs rsvg-convert (Debian: librsvg2-bin).
set -euo pipefail
cd "$(dirname "$0")"
mkdir -p icons
for n in 16 32 48 64 128 256; do
    rsvg-convert -w "$n" -h "$n" makeit4d.svg -o "icons/${n}x${n}.png"
done
