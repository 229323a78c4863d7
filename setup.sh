#!/usr/bin/env bash
# Set up the project on a fresh machine: Debian's libllvm19 for Mitsuba's LLVM variant
# (when missing and we are root), a virtual environment in .venv, and the pinned packages.
# Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")"

have_llvm19() {
    ls /usr/lib/*/libLLVM.so.19* /usr/lib/*/libLLVM-19.so /usr/lib/llvm-19/lib/libLLVM*.so* >/dev/null 2>&1
}

if [ -n "${DRJIT_LIBLLVM_PATH:-}" ] && [ -e "${DRJIT_LIBLLVM_PATH}" ]; then
    :
elif ! have_llvm19; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing Debian's libllvm19 for Mitsuba's llvm_ad_rgb variant"
        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null) \
            || echo "setup: notice: could not install libllvm19; renders fall back to scalar_rgb (slower)"
    else
        echo "setup: notice: libLLVM 19 not found and not root; renders fall back to Mitsuba's scalar_rgb (slower)"
    fi
fi

# Debian's Chromium and its chromedriver for the browser test of the report (tests/test_report.py;
# Selenium is given both binaries and downloads nothing). Without them that test is skipped.
if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing Debian's chromium and chromium-driver for the report's browser test"
        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null) \
            || echo "setup: notice: could not install chromium/chromium-driver; the report's browser test will be skipped"
    else
        echo "setup: notice: chromium or chromedriver not found and not root; the report's browser test will be skipped"
    fi
fi

# Debian's SLURM and MUNGE for the cluster test (tests/test_slurm.py starts a single-node SLURM,
# tests/slurm_local.py). Without them that test is skipped (a failure under .ci/run).
if ! command -v slurmctld >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing Debian's slurm-wlm and munge for the SLURM test"
        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null) \
            || echo "setup: notice: could not install slurm-wlm/munge; the SLURM test will be skipped"
    else
        echo "setup: notice: slurmctld or munged not found and not root; the SLURM test will be skipped"
    fi
fi

PYTHON="${PYTHON:-python3.11}"
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -e ".[test]"
echo "setup: done (.venv ready; activate with '. .venv/bin/activate')"
