#!/usr/bin/env bash
# Sets up roft_sim in ./.venv on Debian/Ubuntu with Python >= 3.11.
#
#   bash scripts/setup.sh          # runtime only
#   bash scripts/setup.sh dev      # plus test tools (pytest, hypothesis, ruff)
#
# System packages: python3-venv (if venv is missing) and a CPU OpenGL backend for offscreen
# rendering (EGL through Mesa: libegl1 libopengl0 libgl1-mesa-dri). They are installed with
# apt-get when this runs as root or with password-less sudo; otherwise the exact command is printed.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"
py="${PYTHON:-python3}"

if ! "$py" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "setup: need Python >= 3.11 as '$py' (set PYTHON=/path/to/python3.11)" >&2
  exit 2
fi

deb_installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
missing=()
if command -v dpkg-query >/dev/null; then
  "$py" -c 'import ensurepip, venv' 2>/dev/null || missing+=("python3-venv")
  for pkg in libegl1 libopengl0 libgl1-mesa-dri; do deb_installed "$pkg" || missing+=("$pkg"); done
fi
if ((${#missing[@]})); then
  if [ "$(id -u)" = 0 ]; then apt_get=(apt-get); elif sudo -n true 2>/dev/null; then apt_get=(sudo apt-get); else apt_get=(); fi
  if ((${#apt_get[@]})); then
    echo "setup: installing Debian packages: ${missing[*]}"
    DEBIAN_FRONTEND=noninteractive "${apt_get[@]}" update -qq
    DEBIAN_FRONTEND=noninteractive "${apt_get[@]}" install -y -qq --no-install-recommends "${missing[@]}"
  else
    echo "setup: missing Debian packages: ${missing[*]}" >&2
    echo "setup: run:  sudo apt-get install -y --no-install-recommends ${missing[*]}" >&2
    case " ${missing[*]} " in *" python3-venv "*) exit 2 ;; esac
    echo "setup: continuing; rendering will fail (render tests are skipped) until they are installed" >&2
  fi
fi

if [ ! -x .venv/bin/python ]; then
  "$py" -m venv .venv
fi
spec="."
[ -n "$extras" ] && spec=".[${extras}]"
.venv/bin/python -m pip install -q --disable-pip-version-check -e "$spec"
echo "setup: ready (.venv/bin/roft-sim)"
