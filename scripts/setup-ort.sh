#!/usr/bin/env bash
# Fetches the ONNX Runtime shared library (onnxruntime 1.31.1, from its
# PyPI wheel) into .ort/ and prints its path. Idempotent; needs python3 + pip.
set -euo pipefail
cd "$(dirname "$0")/.."
lib=.ort/libonnxruntime.so.1.31.1
if [ ! -f "$lib" ]; then
  mkdir -p .ort/wheel
  python3 -m pip download --quiet --no-deps onnxruntime==1.31.1 -d .ort/wheel >&2
  python3 - "$lib" <<'PY'
import glob, sys, zipfile
wheels = glob.glob(".ort/wheel/onnxruntime-1.31.1-*.whl")
if not wheels:
    sys.exit("no onnxruntime 1.31.1 wheel was downloaded")
with zipfile.ZipFile(wheels[0]) as z:
    with z.open("onnxruntime/capi/libonnxruntime.so.1.31.1") as src, open(sys.argv[1], "wb") as dst:
        dst.write(src.read())
PY
  rm -rf .ort/wheel
fi
echo "$PWD/$lib"
