#!/usr/bin/env bash
# Set everything up and open the studio on the bundled demo pair (it runs the best method on it).
#   bash scripts/demo.sh
# Without a display (a server, CI) the studio runs on a virtual X server and writes a screenshot of
# the window with the first result to demo_output/studio.png instead of staying open.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh gui
export QT_QPA_PLATFORM=xcb
if [ -n "${DISPLAY:-}" ] || [ -n "${WAYLAND_DISPLAY:-}" ]; then
    exec .venv/bin/corr-studio --demo
fi
mkdir -p demo_output
echo "demo: no display found: rendering the studio on a virtual X server"
xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/corr-studio --demo --screenshot demo_output/studio.png
echo "demo: wrote demo_output/studio.png (the studio with the demo result)"
.venv/bin/corr demo -o demo_output
