#!/usr/bin/env bash
# setup.sh: prepare a Debian 12 machine (run as root) for building and testing
# the project: system packages for the Mitsuba plugin and bindgen, and the
# project virtualenv .venv with the pinned Python packages.
#
# Idempotent and fast on re-run: apt-get runs only when a package is missing,
# pip only when a pinned requirement is not satisfied.
# Needs network access to the Debian and PyPI registries only (crates.io is
# used later by cargo). The Rust toolchain itself (rustup) is not installed here.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
REQ="$ROOT/scripts/requirements.txt"
PYTHON="${PYTHON:-python3}"

log() { printf '[setup] %s\n' "$*"; }

# --- system packages -----------------------------------------------------
# libllvm19: LLVM for Dr.Jit's llvm_* variants (Debian's LLVM 14/15 are refused
#            or crash; see docs/mitsuba.md).
# libclang-dev: bindgen. g++, make: the plugin build.
# chromium: the material explorer's tests (headless WebGL2 through SwiftShader;
#           tests/test_explorer.py, docs/explorer.md).
PKGS=(libllvm19 libclang-dev g++ make chromium)
# A Debian python3 needs python3-venv for `python3 -m venv` (ensurepip).
if ! command -v "$PYTHON" >/dev/null 2>&1; then
    PKGS+=(python3 python3-venv)
elif ! "$PYTHON" -c 'import ensurepip, venv' >/dev/null 2>&1; then
    PKGS+=(python3-venv)
fi

missing=()
for p in "${PKGS[@]}"; do
    if ! dpkg -s "$p" 2>/dev/null | grep -q '^Status: install ok installed'; then
        missing+=("$p")
    fi
done
if ((${#missing[@]})); then
    log "installing missing packages: ${missing[*]}"
    if [ "$(id -u)" -ne 0 ]; then
        echo "setup.sh: packages missing (${missing[*]}) and not running as root" >&2
        exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update
    apt-get install -y --no-install-recommends "${missing[@]}"
else
    log "system packages present: ${PKGS[*]}"
fi

LIBLLVM=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
[ -e "$LIBLLVM" ] || log "warning: $LIBLLVM not found (llvm_* variants will not run)"

# --- virtualenv ----------------------------------------------------------
if [ ! -x "$VENV/bin/python" ]; then
    log "creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi

# Every pinned requirement installed at exactly its version? (no network)
if "$VENV/bin/python" - "$REQ" <<'EOF'
import re, sys
from importlib import metadata
bad = []
for line in open(sys.argv[1]):
    line = line.split('#', 1)[0].strip()
    if not line:
        continue
    name, ver = re.fullmatch(r'([A-Za-z0-9_.\-]+)==(\S+)', line).groups()
    try:
        have = metadata.version(name)
    except metadata.PackageNotFoundError:
        have = None
    if have != ver:
        bad.append(f'{name} (have {have}, want {ver})')
if bad:
    print('[setup] pip needed for: ' + ', '.join(bad))
    sys.exit(1)
EOF
then
    log "python requirements satisfied"
else
    "$VENV/bin/python" -m pip install --disable-pip-version-check -r "$REQ"
fi

log "done. Build with: make core plugin   (venv: $VENV)"
