#!/usr/bin/env bash
# Set everything up and run the whole test suite (GUI tests on an Xvfb virtual display).
#   bash scripts/test.sh [pytest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh gui,test,dist
# pytest-xvfb starts a virtual X server for the session; Qt renders through its xcb platform
export QT_QPA_PLATFORM=xcb
exec .venv/bin/python -m pytest "$@"
