#!/usr/bin/env bash
# The whole test suite, with its set-up, on a fresh machine (Debian bookworm + rustup) or here.
# CI (.ci/run) calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."

# Set-up: the embedded target (idempotent; quick when present).
rustup target add thumbv7em-none-eabihf thumbv6m-none-eabi >/dev/null
# QEMU >= 10 and its instruction-counting plugin for the emulated-board (PIL) tests.
./tools/setup-qemu.sh
# Python venv for the MF4 reader's tests (hil-host/tests/mf4.rs): asammdf writes the .mf4 files
# the reader must read, as logger tools export them. Made once, then quick: it is remade only
# when tools/py/requirements.txt changes. The tests fail rather than skip without it.
py_venv="${CARGO_TARGET_DIR:-target}/py-venv"
if ! cmp -s tools/py/requirements.txt "$py_venv/requirements.txt" 2>/dev/null; then
  python3 -c 'import ensurepip' 2>/dev/null || { apt-get update -qq && apt-get install -y -qq python3-venv; }
  rm -rf "$py_venv"
  python3 -m venv "$py_venv"
  "$py_venv/bin/pip" install --quiet --disable-pip-version-check -r tools/py/requirements.txt
  cp tools/py/requirements.txt "$py_venv/requirements.txt"
fi
export HIL_REQUIRE_PY=1
# Headless Chromium (Debian's `chromium`) for the HTML report tests (hil-host/tests/report_html.rs):
# installed when missing (as root, apt-get update first); the tests fail rather than skip without it.
if ! command -v chromium >/dev/null 2>&1; then
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium
fi
export HIL_REQUIRE_CHROMIUM=1

# The house rules (CONTRIBUTING.md): a tree that is not formatted or not lint-clean fails here,
# before anything slow runs.
echo "== cargo fmt --check"
cargo fmt --all --check
echo "== clippy, host crates [${SECONDS} s]"
cargo clippy --workspace --exclude firmware --exclude firmware-qemu --all-targets --locked -- -D warnings
echo "== clippy, target crates (thumbv7em-none-eabihf) [${SECONDS} s]"
cargo clippy -p firmware -p firmware-qemu --target thumbv7em-none-eabihf --locked -- -D warnings
# model-core is for FPU-less ECUs too (Cortex-M0+: no FPU, no 64-bit multiply instruction).
echo "== model-core for thumbv6m-none-eabi (Cortex-M0+) [${SECONDS} s]"
cargo check -p model-core --target thumbv6m-none-eabi --locked

# One target directory for everything: host tests, the firmware build.
# The emulated-board image the PIL tests run under QEMU (built first, so the tests find it).
echo "== firmware for QEMU's netduinoplus2 (thumbv7em-none-eabihf, profile firmware) [${SECONDS} s]"
cargo build --profile firmware --locked -p firmware-qemu --target thumbv7em-none-eabihf

echo "== host tests (model-core, paper tests, hil-host) [${SECONDS} s]"
# The PIL tests fail rather than skip when QEMU is missing. --no-fail-fast: a failing test
# binary does not hide the failures of the binaries after it (the run still fails).
HIL_REQUIRE_QEMU=1 cargo test --workspace --locked --no-fail-fast

echo "== firmware for the STM32F405 (thumbv7em-none-eabihf, profile firmware) [${SECONDS} s]"
cargo build --profile firmware --locked -p firmware --target thumbv7em-none-eabihf
elf="${CARGO_TARGET_DIR:-target}/thumbv7em-none-eabihf/firmware/firmware"
if command -v size >/dev/null 2>&1; then
  # text = flash code + rodata, data = initialised RAM (also in flash), bss = zeroed RAM.
  size -A "$elf" | awk '/^\.(vector_table|text|rodata|data|bss|uninit)/ {print}'
  size "$elf"
  # Flash = text + data (initial values are copied from flash), static RAM = data + bss
  # (Berkeley bss includes .uninit, the RTT buffer); no heap. Goals: 96 KiB, 24 KiB.
  size "$elf" | awk 'NR == 2 {
    flash = $1 + $2; ram = $2 + $3;
    printf "flash %d B (%.1f KiB, goal < 96 KiB), static RAM %d B (%.1f KiB, goal < 24 KiB)\n", flash, flash / 1024, ram, ram / 1024;
    if (flash >= 96 * 1024 || ram >= 24 * 1024) print "WARNING: firmware over its size goal";
  }'
fi
echo "== all done in ${SECONDS} s"
