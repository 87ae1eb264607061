#!/usr/bin/env bash
# Set everything up and run the main job on the bundled demo pair.
#   bash scripts/demo.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/corr demo -o demo_output
