#!/usr/bin/env bash
# Installs what cargo does not: the ONNX Runtime shared library (from the `onnxruntime`
# wheel on PyPI) and a Python virtual environment with the external checkers.
# Idempotent: rerunning it re-checks what is there and repairs what an interrupted run left
# (a truncated library, a missing link, a virtual environment without pip).
#
#   scripts/setup.sh               everything
#   scripts/setup.sh --no-python   without the Python checkers (a bare .venv still gives the
#                                  pip that fetches the wheel; cargo-fuzz is still installed)
#
# LIDAR_HAR_ORT_WHEEL=/path/to/onnxruntime-*.whl takes the library from that wheel instead of
# PyPI (an offline machine). Everything lands inside the repository, in `.deps/` and `.venv/`
# (both git-ignored). cargo-fuzz comes from crates.io; where it cannot be had (offline) the
# set-up warns and goes on: only scripts/fuzz.sh (scripts/test.sh's last step) needs it.
set -euo pipefail

ORT_VERSION="1.31.1"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEPS="$ROOT/.deps"
ORT_DIR="$DEPS/onnxruntime"
ORT_LIB="$ORT_DIR/libonnxruntime.so.$ORT_VERSION"
# The library's checksum, written once it is in place and linked: without it (or when the
# library no longer matches it) an earlier run was interrupted, and the library is fetched again.
ORT_CHECKSUM="$ORT_DIR/installed.sha256"
VENV="$ROOT/.venv"
PY_REQUIREMENTS="$ROOT/scripts/requirements-checkers.txt"
WITH_PYTHON=1

for arg in "$@"; do
    case "$arg" in
        --no-python) WITH_PYTHON=0 ;;
        -h | --help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
        *) echo "setup: unknown option '$arg' (try --help)" >&2; exit 2 ;;
    esac
done

say() { printf '\033[1msetup:\033[0m %s\n' "$*"; }
fail() {
    printf '\033[31msetup: FAILED:\033[0m %s\n' "$1" >&2
    printf '       fix: %s\n' "$2" >&2
    exit 1
}

need() {
    command -v "$1" >/dev/null 2>&1 || fail "'$1' is not installed" "$2"
}

need cargo "install Rust with rustup (https://rustup.rs), then rerun scripts/setup.sh"
need python3 "apt-get install python3 python3-venv python3-pip"

# rustup brings no linker or C compiler; the build needs both (bundled SQLite and zstd, build
# scripts, cargo-fuzz).
if ! command -v cc >/dev/null || ! command -v c++ >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "installing build-essential from Debian (a C and C++ compiler and linker)"
        apt-get update -qq && apt-get install -y -qq build-essential >/dev/null \
            || fail "apt-get could not install build-essential" "run 'apt-get install build-essential' as root"
    else
        fail "no C compiler and linker ('cc', 'c++')" "run 'sudo apt-get install build-essential'"
    fi
fi

# Debian installs venv and pip separately; install them when we are root and they are missing.
if ! python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "installing python3-venv and python3-pip from Debian"
        apt-get update -qq && apt-get install -y -qq python3-venv python3-pip >/dev/null \
            || fail "apt-get could not install python3-venv" "run 'apt-get install python3-venv python3-pip' as root"
    else
        fail "python3 has no 'venv' module" "run 'sudo apt-get install python3-venv python3-pip'"
    fi
fi

# Tools the multi-process tests use: unshare (util-linux) and ip (iproute2).
if ! command -v unshare >/dev/null || ! command -v ip >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "installing util-linux and iproute2 from Debian (private network namespaces for DDS tests)"
        apt-get update -qq && apt-get install -y -qq util-linux iproute2 >/dev/null \
            || fail "apt-get could not install util-linux/iproute2" "run 'apt-get install util-linux iproute2' as root"
    else
        say "warning: 'unshare' or 'ip' missing; DDS tests will skip, and fail under scripts/test.sh and CI (LIDAR_HAR_REQUIRE_CHECKERS=1): sudo apt-get install util-linux iproute2"
    fi
fi

# --- Python virtual environment (checkers; also the pip used to fetch the ONNX Runtime wheel).
# `python3 -m venv` makes bin/python first and pip last: one interrupted in between has no pip.
if ! "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
    say "creating the virtual environment $VENV"
    python3 -m venv --clear "$VENV" || fail "python3 -m venv $VENV failed" "apt-get install python3-venv, then rerun"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check -q)

# --- ONNX Runtime shared library, taken out of the PyPI wheel
ort_linked() {
    [ "$(readlink "$ORT_DIR/libonnxruntime.so" 2>/dev/null)" = "libonnxruntime.so.$ORT_VERSION" ]
}
ort_installed() {
    ort_linked && [ -f "$ORT_CHECKSUM" ] \
        && (cd "$ORT_DIR" && sha256sum --check --status "$ORT_CHECKSUM")
}
# A library and its link without a checksum come from a set-up before checksums, complete or
# not: fetched again, but kept, with a warning, where no wheel can be had (an offline robot).
unverified_install() {
    ort_linked && [ -f "$ORT_LIB" ] && [ ! -f "$ORT_CHECKSUM" ]
}
# Keeps an unverified library when there is one, else fails: `$1` says why no wheel can be
# had, `$2` the fix.
no_wheel() {
    if [ "$UNVERIFIED" = 1 ]; then
        say "warning: $1; keeping the ONNX Runtime library already at $ORT_LIB, unverified (if model commands end with 'Bus error', delete .deps/ and rerun scripts/setup.sh)"
    else
        fail "$1" "$2"
    fi
}
if ort_installed; then
    say "ONNX Runtime $ORT_VERSION already at $ORT_LIB"
else
    UNVERIFIED=0
    unverified_install && UNVERIFIED=1
    WHEEL_DIR="$DEPS/.wheel"
    trap 'rm -rf "$WHEEL_DIR"' EXIT
    wheel=""
    if [ -n "${LIDAR_HAR_ORT_WHEEL:-}" ]; then
        if [ -f "$LIDAR_HAR_ORT_WHEEL" ]; then
            wheel="$LIDAR_HAR_ORT_WHEEL"
            say "taking the ONNX Runtime library from $wheel"
        else
            no_wheel "LIDAR_HAR_ORT_WHEEL=$LIDAR_HAR_ORT_WHEEL is not a file" \
                "point it at an onnxruntime-$ORT_VERSION wheel, or unset it to fetch one from PyPI"
        fi
    else
        say "fetching the onnxruntime==$ORT_VERSION wheel from PyPI for its shared library"
        if "${PIP[@]}" download "onnxruntime==$ORT_VERSION" --no-deps --only-binary=:all: -d "$WHEEL_DIR"; then
            wheel="$(ls "$WHEEL_DIR"/onnxruntime-*.whl | head -n1)"
        else
            no_wheel "pip could not download onnxruntime==$ORT_VERSION from PyPI" \
                "check that PyPI is reachable (pip config, proxy) and that a wheel exists for $(uname -m), or set LIDAR_HAR_ORT_WHEEL to a wheel at hand"
        fi
    fi
    if [ -n "$wheel" ]; then
        mkdir -p "$ORT_DIR"
        # Each library is written beside its final name and renamed once complete (zipfile
        # checks its CRC as it reads), so a run stopped half-way never leaves a truncated
        # library there.
        "$VENV/bin/python" - "$wheel" "$ORT_DIR" <<'PY' || fail "could not extract libonnxruntime from $wheel" "free some disk space (about 30 MB) and rerun scripts/setup.sh"
import sys, zipfile, os, shutil
wheel, dest = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    libs = [n for n in z.namelist() if os.path.basename(n).startswith("libonnxruntime.so")]
    if not libs:
        sys.exit("no libonnxruntime.so in " + wheel)
    for name in libs:
        final = os.path.join(dest, os.path.basename(name))
        partial = final + ".partial"
        with z.open(name) as src, open(partial, "wb") as dst:
            shutil.copyfileobj(src, dst)
            dst.flush()
            os.fsync(dst.fileno())
        os.replace(partial, final)
PY
        [ -f "$ORT_LIB" ] || fail "the wheel did not contain libonnxruntime.so.$ORT_VERSION" \
            "update ORT_VERSION in scripts/setup.sh to the version in the wheel"
        ln -sfn "libonnxruntime.so.$ORT_VERSION" "$ORT_DIR/libonnxruntime.so"
        (cd "$ORT_DIR" && sha256sum "libonnxruntime.so.$ORT_VERSION" > "$ORT_CHECKSUM.partial") \
            && mv "$ORT_CHECKSUM.partial" "$ORT_CHECKSUM" \
            || fail "could not write $ORT_CHECKSUM" "free some disk space and rerun scripts/setup.sh"
        say "ONNX Runtime installed at $ORT_LIB"
    fi
fi

# --- External checkers (rosbags, mcap, mcap-ros2-support, cyclonedds); pip skips what is there.
if [ "$WITH_PYTHON" = 1 ]; then
    if [ "$(uname -m)" != x86_64 ]; then
        say "warning: PyPI has cyclonedds wheels for x86_64 only; on $(uname -m) it is left out, and the Cyclone DDS interoperability test fails under scripts/test.sh"
    fi
    say "installing Python checkers into $VENV from $PY_REQUIREMENTS"
    "${PIP[@]}" install -r "$PY_REQUIREMENTS" || fail "pip install -r $PY_REQUIREMENTS failed" \
        "check that PyPI is reachable; the failing package is named above"
fi

# --- cargo-fuzz (scripts/fuzz.sh runs the fuzz targets briefly in the test suite). Without it
# everything else still builds and runs, so an offline machine is warned, not stopped.
FUZZ_NOTE=""
if cargo fuzz --version >/dev/null 2>&1; then
    say "cargo-fuzz already installed"
else
    say "installing cargo-fuzz from crates.io (a minute or two)"
    if ! cargo install cargo-fuzz --locked --quiet; then
        say "warning: cargo install cargo-fuzz failed (is crates.io reachable?); scripts/fuzz.sh, and so scripts/test.sh without --quick, fail until it is installed: rerun scripts/setup.sh, or run 'cargo install cargo-fuzz --locked', once crates.io is reachable"
        FUZZ_NOTE=" (without cargo-fuzz: see the warning above)"
    fi
fi

say "done${FUZZ_NOTE}. ONNX Runtime: $ORT_LIB"
