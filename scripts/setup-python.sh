#!/usr/bin/env bash
# Creates the Python virtual environment of the rosbag2 tests and of
# scripts/tum_to_rosbag2.py in .venv/ with the pinned packages below (`rosbags` writes
# and reads ROS 2 bags, `pillow` encodes and decodes their PNG and JPEG images) and
# prints its python's path. Idempotent; needs python3 with venv and pip.
set -euo pipefail
cd "$(dirname "$0")/.."
packages=(rosbags==0.11.9 pillow==13.0.0)
python=.venv/bin/python
stamp=.venv/.opengs-packages
if [ ! -x "$python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "${packages[*]}" ]; then
  python3 -m venv .venv >&2
  "$python" -m pip install --quiet --disable-pip-version-check "${packages[@]}" >&2
  echo "${packages[*]}" >"$stamp"
fi
echo "$PWD/$python"
