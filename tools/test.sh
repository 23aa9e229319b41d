#!/usr/bin/env bash
# The whole test suite, with its set-up, on a fresh machine (Debian bookworm + rustup) or here.
# CI (.ci/run) calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."

# Set-up: the embedded target (idempotent; quick when present).
rustup target add thumbv7em-none-eabihf thumbv6m-none-eabi >/dev/null
# QEMU >= 10 and its instruction-counting plugin for the emulated-board (PIL) tests.
./tools/setup-qemu.sh

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
# The PIL tests fail rather than skip when QEMU is missing.
HIL_REQUIRE_QEMU=1 cargo test --workspace --locked

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
