//! Helpers for the end-to-end tests in `tests/`: locate the real
//! `terraplan` binary, the shared test data and the validators' venv.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_path_buf()
}

/// The `terraplan` binary built by `cargo build --workspace --bins` (the
/// test command does that first); `TERRAPLAN_BIN` overrides it.
pub fn terraplan_bin() -> PathBuf {
    if let Ok(p) = std::env::var("TERRAPLAN_BIN") {
        return PathBuf::from(p);
    }
    let target = std::env::var("CARGO_TARGET_DIR").map_or_else(|_| workspace().join("target"), PathBuf::from);
    let bin = target.join("debug").join("terraplan");
    assert!(
        bin.exists(),
        "{} is missing: run `cargo build --workspace --bins` first (scripts/test.sh does)",
        bin.display()
    );
    bin
}

/// A file of the shared real-world test data (`../shared/data` beside the
/// repository; `TERRAPLAN_SHARED_DATA` overrides it).
pub fn shared_data(rel: &str) -> PathBuf {
    let base = std::env::var("TERRAPLAN_SHARED_DATA")
        .map_or_else(|_| workspace().join("../shared/data"), PathBuf::from);
    let p = base.join(rel);
    assert!(p.exists(), "shared test data {} is missing", p.display());
    p
}

/// Python of the validators' venv (made by `scripts/setup.sh --with-validators`).
pub fn venv_python() -> PathBuf {
    let venv = std::env::var("TERRAPLAN_VENV").map_or_else(|_| workspace().join(".venv"), PathBuf::from);
    let py = venv.join("bin").join("python");
    assert!(
        py.exists(),
        "{} is missing: run `bash scripts/setup.sh --with-validators` (scripts/test.sh does)",
        py.display()
    );
    py
}

/// Run `terraplan` with `args`.
pub fn terraplan(args: &[&str]) -> Output {
    Command::new(terraplan_bin()).args(args).output().expect("run terraplan")
}

/// Run a validator script from `tests/validators` with the venv's Python.
pub fn validator(script: &str, args: &[&Path]) -> Output {
    Command::new(venv_python())
        .arg(workspace().join("tests/validators").join(script))
        .args(args)
        .output()
        .expect("run validator")
}

pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}
