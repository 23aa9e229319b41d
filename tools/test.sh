#!/usr/bin/env bash
# The whole test suite, with its set-up, on a fresh machine (Debian bookworm + rustup) or here.
# CI (.ci/run) calls exactly this.
set -euo pipefail
cd "$(dirname "$0")/.."

# Set-up: the embedded target (idempotent; quick when present).
rustup target add thumbv7em-none-eabihf >/dev/null

# One target directory for everything: host tests, the firmware build.
echo "== host tests (model-core, paper tests, hil-host)"
cargo test --workspace --locked

echo "== firmware for the STM32F405 (thumbv7em-none-eabihf, release)"
cargo build --release --locked -p firmware --target thumbv7em-none-eabihf
elf=target/thumbv7em-none-eabihf/release/firmware
if command -v size >/dev/null 2>&1; then
  # text = flash code + rodata, data = initialised RAM (also in flash), bss = zeroed RAM.
  size -A "$elf" | awk '/^\.(vector_table|text|rodata|data|bss|uninit)/ {print}'
  size "$elf"
fi
