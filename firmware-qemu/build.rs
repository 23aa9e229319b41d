//! Puts the workspace's memory.x on the linker's search path: QEMU's netduinoplus2 models the
//! STM32F405 with the same 1 MiB flash at 0x08000000 and 128 KiB SRAM at 0x20000000.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let memory_x = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../memory.x");
    fs::copy(&memory_x, out.join("memory.x")).expect("memory.x at the workspace root");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
}
