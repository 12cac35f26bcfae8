#!/usr/bin/env bash
# Installs what the tests need on a fresh machine, then runs the whole test suite.
#
#   - Debian packages (as root, through apt-get, only when missing): mesa-vulkan-drivers
#     (lavapipe, the CPU Vulkan adapter the GPU tests run on), xvfb (the editor's window tests),
#     ffmpeg (video export tests).
#   - The ONNX Runtime 1.31 shared library from PyPI's onnxruntime wheel, into
#     ${XDG_DATA_HOME:-~/.local/share}/makeit4d/ort (where makeit4d looks for it).
#   - The Khronos glTF validator (npm gltf-validator, pinned) into
#     ${XDG_CACHE_HOME:-~/.cache}/makeit4d/gltf-validator, for the .glb export's test (Debian's
#     nodejs and npm first when npm is missing).
#   - OpenAI's CLIP merges list (bpe_simple_vocab_16e6.txt.gz, MIT) out of PyPI's open-clip-torch
#     3.3.0 wheel, into ${XDG_CACHE_HOME:-~/.cache}/makeit4d/clip, for the tokenizer's known-answer
#     tests.
#   - Rust crates through cargo (Cargo.lock pins them).
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() {
    if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
        echo "tests/run.sh: need root to install Debian packages: $*" >&2; return 1; fi
}

missing=()
for pkg in mesa-vulkan-drivers libvulkan1 xvfb ffmpeg; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "tests/run.sh: installing ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

ort_dir="${XDG_DATA_HOME:-$HOME/.local/share}/makeit4d/ort"
ort_lib="$ort_dir/onnxruntime/capi/libonnxruntime.so.1.31.1"
if [ ! -e "$ort_lib" ]; then
    echo "tests/run.sh: installing ONNX Runtime 1.31.1 into $ort_dir"
    python3 -m pip install --quiet --disable-pip-version-check --no-deps --target "$ort_dir" onnxruntime==1.31.1
fi
export ORT_DYLIB_PATH="$ort_lib"

if ! command -v npm >/dev/null; then
    echo "tests/run.sh: installing nodejs npm"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nodejs npm >/dev/null
fi
validator_dir="${XDG_CACHE_HOME:-$HOME/.cache}/makeit4d/gltf-validator"
if [ ! -e "$validator_dir/node_modules/gltf-validator/package.json" ]; then
    echo "tests/run.sh: installing gltf-validator 2.0.0-dev.3.10 into $validator_dir"
    npm install --silent --no-audit --no-fund --prefix "$validator_dir" gltf-validator@2.0.0-dev.3.10 >/dev/null
fi
export MAKEIT4D_GLTF_VALIDATOR="$validator_dir/node_modules"

clip_dir="${XDG_CACHE_HOME:-$HOME/.cache}/makeit4d/clip"
clip_bpe="$clip_dir/bpe_simple_vocab_16e6.txt.gz"
if [ ! -e "$clip_bpe" ]; then
    echo "tests/run.sh: fetching the CLIP merges list (open-clip-torch 3.3.0) into $clip_dir"
    mkdir -p "$clip_dir"
    python3 -m pip download --quiet --disable-pip-version-check --no-deps -d "$clip_dir/wheel" open-clip-torch==3.3.0
    python3 - "$clip_dir" <<'PY'
import glob, sys, zipfile
folder = sys.argv[1]
wheel = glob.glob(folder + "/wheel/open_clip_torch-3.3.0-*.whl")[0]
with zipfile.ZipFile(wheel) as z, open(folder + "/bpe_simple_vocab_16e6.txt.gz", "wb") as out:
    out.write(z.read("open_clip/bpe_simple_vocab_16e6.txt.gz"))
PY
    rm -rf "$clip_dir/wheel"
fi
export MAKEIT4D_CLIP_BPE="$clip_bpe"

cargo test --locked --all-targets "$@"
