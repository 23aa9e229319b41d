//! The Python venv of the tests that check hil-host against independent Python readers and
//! writers (asammdf for MF4, pya2ldb for A2L): `target/py-venv`, made by tools/test.sh from
//! tools/py/requirements.txt.
use std::path::{Path, PathBuf};

/// The repository's root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The venv's python, or None (skip) when it is missing and HIL_REQUIRE_PY is unset.
pub fn python() -> Option<PathBuf> {
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root().join("target"), PathBuf::from);
    let py = target.join("py-venv/bin/python");
    if py.exists() {
        return Some(py);
    }
    if std::env::var_os("HIL_REQUIRE_PY").is_some() {
        panic!(
            "HIL_REQUIRE_PY is set but {} is missing: run tools/test.sh (it creates the venv from tools/py/requirements.txt)",
            py.display()
        );
    }
    eprintln!(
        "SKIP: {} is missing (python3 -m venv target/py-venv && target/py-venv/bin/pip install -r tools/py/requirements.txt)",
        py.display()
    );
    None
}
