//! Whether the Python reference scripts of the tests can run here (`scripts/*.py`, numpy and scipy): tests that
//! compare with them print "skipped" where they cannot (CI installs both).

/// Whether `python3` runs and imports every module of `modules`.
pub fn python3_with(modules: &[&str]) -> bool {
    let imports = modules
        .iter()
        .map(|m| format!("import {m}"))
        .collect::<Vec<_>>()
        .join("; ");
    std::process::Command::new("python3")
        .args(["-c", &imports])
        .output()
        .is_ok_and(|o| o.status.success())
}
