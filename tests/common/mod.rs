//! Helpers of the binary's integration tests: running the built `any4d`, reading its output, and the train
//! crate's test fixtures (procedural store, tiny VAE config, parameter dumps), shared rather than copied.
// Each test file compiles its own copy of this module and uses only some of it.
#![allow(dead_code)]

use std::process::{Command, Output};

#[path = "../../train/tests/common/mod.rs"]
pub mod fixtures;

/// Runs the built `any4d` binary with `args` and waits for it.
pub fn any4d(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_any4d"))
        .args(args)
        .output()
        .expect("the any4d binary runs")
}

/// (stdout, stderr) of a finished command, as text.
pub fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
