#!/usr/bin/env bash
# Set up the project in a local virtual environment (.venv) on a fresh machine with only python3.
#   bash scripts/setup.sh [EXTRAS]     e.g. "gui,test"
# As root, missing Debian packages (python3-venv; with the gui/test extras the X virtual display
# and the libraries Qt's xcb platform and VTK need) are installed with apt-get.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"
PY="${PYTHON:-python3}"

apt_install() {
    # install the given Debian packages that are not installed yet (root only)
    [ "$(id -u)" = 0 ] || return 0
    command -v apt-get >/dev/null 2>&1 || return 0
    local missing=()
    for p in "$@"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
    [ ${#missing[@]} -eq 0 ] && return 0
    echo "setup: installing Debian packages: ${missing[*]}"
    DEBIAN_FRONTEND=noninteractive apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

if [ ! -x .venv/bin/python ]; then
    if ! "$PY" -m venv .venv 2>/dev/null; then
        rm -rf .venv
        apt_install python3-venv python3-pip
        "$PY" -m venv .venv
    fi
fi

if [[ "$extras" == *gui* || "$extras" == *test* ]]; then
    apt_install xvfb xauth libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-render-util0 \
        libxcb-xinerama0 libxcb-randr0 libxcb-shape0 libxcb-xkb1 libxcb-cursor0 libxkbcommon-x11-0 \
        libxkbcommon0 libegl1 libgl1 libglx-mesa0 libgl1-mesa-dri libfontconfig1 libdbus-1-3 libxrender1
fi

spec="."
[ -n "$extras" ] && spec=".[${extras}]"
# reinstall only when the dependency list or the extras changed
stamp=".venv/.corrlib-installed"
want="$(sha1sum pyproject.toml | cut -d' ' -f1) ${extras}"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    echo "setup: installing corrlib${extras:+ [$extras]} into .venv (first run takes a few minutes)"
    .venv/bin/python -m pip install -q --upgrade pip >/dev/null
    .venv/bin/python -m pip install -q -e "$spec"
    echo "$want" > "$stamp"
    echo "setup: compiling the numerical kernels (once, under a minute)"
fi
# compile the numerical kernels now (numba caches them next to the sources), not in the first run of a method;
# a second setup only loads them (about a second)
.venv/bin/python -c "from corrlib.warmup import warm_up; warm_up()"
