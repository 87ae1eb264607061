#!/usr/bin/env bash
# Set everything up and run the whole test suite (GUI tests on an Xvfb virtual display).
#   bash scripts/test.sh [pytest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh gui,test,dist
# pytest-xvfb starts a virtual X server for the session; Qt renders through its xcb platform
export QT_QPA_PLATFORM=xcb
# one test process per core (at most 2; a file's tests stay in one process, so module fixtures are built once);
# CORR_TEST_WORKERS=0 runs everything in this process, and a "-n N" among the arguments wins
workers="${CORR_TEST_WORKERS:-$(python3 -c 'import os; print(min(2, len(os.sched_getaffinity(0))))')}"
if ! [[ "$workers" =~ ^[0-9]+$ ]]; then
    echo "error: CORR_TEST_WORKERS must be a whole number of test processes (0 or 1: one process), got '$workers'" >&2
    exit 2
fi
if [ "$workers" -gt 1 ]; then
    exec .venv/bin/python -m pytest -n "$workers" --dist loadfile "$@"
fi
exec .venv/bin/python -m pytest "$@"
