#!/usr/bin/env bash
# The main job: a closed-loop run of all three actuators. Until the emulated-board (QEMU) route
# lands it runs natively: the firmware's control code from model-core against the plant models.
set -euo pipefail
cd "$(dirname "$0")/.."
rustup target add thumbv7em-none-eabihf >/dev/null
cargo run --release --locked -p hil-host -- run "${@:-scenarios/default.toml}"
