//! End-to-end and cross-process tests for ellipso.
//!
//! The library part holds helpers shared by the scenarios under `tests/tests/`: locating the
//! `ellipso` binary that cargo built beside the test executables, temporary session folders, and
//! process-group cleanup. Scenarios drive the real interfaces: the host's serial code on a
//! pseudo-terminal, the firmware on an emulated MCU, aravis against its fake GigE camera on
//! loopback inside a private network namespace.

pub mod browser;
pub mod fit_fixture;
pub mod qemu;

use std::path::PathBuf;

/// A shipped scene file (`sim/scenes/<name>`).
pub fn shipped_scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("sim")
        .join("scenes")
        .join(name)
}

/// Path of the `ellipso` binary built by the same `cargo test` invocation.
///
/// Cargo puts integration-test executables in `target/<profile>/deps/` and binaries in
/// `target/<profile>/`; `ELLIPSO_BIN` overrides the lookup.
pub fn ellipso_bin() -> PathBuf {
    if let Some(p) = std::env::var_os("ELLIPSO_BIN") {
        return PathBuf::from(p);
    }
    let exe = std::env::current_exe().expect("current_exe");
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable lives in target/<profile>/deps");
    let bin = profile_dir.join(format!("ellipso{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "the ellipso binary is missing at {}: run the tests with `cargo test --workspace`",
        bin.display()
    );
    bin
}
