//! The one runner of the Python references that `any4d bench …` compares against (numpy, scipy, PyTorch), with one
//! policy: a reference that cannot run here is skipped with its reason; one that runs and fails is an error.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, bail};

/// Exit code by which a reference script says that a Python package it needs is not installed.
pub const EXIT_MISSING_PACKAGE: i32 = 3;

/// A Python script to run: interpreter, script, arguments; BLAS and OpenMP pools are limited to `threads`.
pub struct PythonReference<'a> {
    /// The interpreter (`--python`).
    pub python: &'a Path,
    /// The script (`--script`).
    pub script: &'a Path,
    /// Its arguments.
    pub args: Vec<String>,
    /// Threads of numpy's and torch's pools (`OMP_NUM_THREADS` and friends).
    pub threads: usize,
}

/// Why a reference did not run (it is then left out of the report, which says so).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped(pub String);

impl<'a> PythonReference<'a> {
    /// A reference's benchmark mode on one core: `script --bench INPUT --repeat REPEAT`.
    pub fn bench(python: &'a Path, script: &'a Path, input: &Path, repeat: usize) -> Self {
        PythonReference {
            python,
            script,
            args: vec![
                "--bench".into(),
                input.display().to_string(),
                "--repeat".into(),
                repeat.to_string(),
            ],
            threads: 1,
        }
    }

    /// Runs the script and returns the last line it printed on stdout (the references print one JSON line).
    /// `Ok(Err(Skipped))` when it cannot run here: no interpreter, no script, or a missing package (exit code
    /// [`EXIT_MISSING_PACKAGE`] or Python's `No module named`). Any other failure is an error naming the script and
    /// carrying its stderr.
    pub fn last_line(&self) -> anyhow::Result<Result<String, Skipped>> {
        if !self.script.is_file() {
            return Ok(Err(Skipped(format!(
                "reference script {} not found (run from the repository root or pass --script)",
                self.script.display()
            ))));
        }
        let threads = self.threads.to_string();
        let out = Command::new(self.python)
            .arg(self.script)
            .args(&self.args)
            .env("OMP_NUM_THREADS", &threads)
            .env("OPENBLAS_NUM_THREADS", &threads)
            .env("MKL_NUM_THREADS", &threads)
            .output();
        let out = match out {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Err(Skipped(format!("{} not found", self.python.display()))));
            }
            other => other.with_context(|| format!("running {}", self.python.display()))?,
        };
        let stderr = String::from_utf8_lossy(&out.stderr);
        if !out.status.success() {
            if out.status.code() == Some(EXIT_MISSING_PACKAGE) || stderr.contains("No module named") {
                let why = stderr.trim().lines().last().unwrap_or("a Python package is missing");
                return Ok(Err(Skipped(format!("{}: {why}", self.script.display()))));
            }
            bail!(
                "{} {} failed ({}): {}",
                self.python.display(),
                self.script.display(),
                out.status,
                stderr.trim()
            );
        }
        let stdout = String::from_utf8_lossy(&out.stdout);
        let line = stdout
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .with_context(|| format!("{} printed nothing", self.script.display()))?;
        Ok(Ok(line.to_string()))
    }

    /// [`Self::last_line`] parsed as JSON into `T`; unreadable output is an error naming the script.
    pub fn json<T: serde::de::DeserializeOwned>(&self) -> anyhow::Result<Result<T, Skipped>> {
        Ok(match self.last_line()? {
            Ok(line) => Ok(serde_json::from_str(&line)
                .with_context(|| format!("{}: unexpected output {line:?}", self.script.display()))?),
            Err(skipped) => Err(skipped),
        })
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    /// A fake reference: `sh SCRIPT` with `body` as the script.
    fn fake(body: &str) -> (tempfile::TempDir, PathBuf) {
        let tmp = tempfile::tempdir().expect("temp dir");
        let script = tmp.path().join("fake.sh");
        std::fs::write(&script, body).expect("write");
        (tmp, script)
    }

    fn run(script: &Path, python: &str, args: &[&str]) -> anyhow::Result<Result<String, Skipped>> {
        PythonReference {
            python: Path::new(python),
            script,
            args: args.iter().map(|s| s.to_string()).collect(),
            threads: 1,
        }
        .last_line()
    }

    #[test]
    fn the_last_printed_line_is_returned_with_the_arguments_passed_through() {
        let (_tmp, script) = fake("echo warming up\necho \"{\\\"a\\\": $2}\"\necho\n");
        let line = run(&script, "sh", &["--a", "7"]).expect("runs").expect("available");
        assert_eq!(line, "{\"a\": 7}");
        #[derive(serde::Deserialize)]
        struct A {
            a: u32,
        }
        let parsed: A = PythonReference {
            python: Path::new("sh"),
            script: &script,
            args: vec!["--a".into(), "9".into()],
            threads: 1,
        }
        .json()
        .expect("runs")
        .expect("available");
        assert_eq!(parsed.a, 9);
    }

    #[test]
    fn missing_interpreter_script_or_package_are_reasons() {
        let (tmp, script) = fake("echo 'bench: torch is not installed' >&2\nexit 3\n");
        let why = run(&script, "sh", &[]).expect("runs").expect_err("skipped");
        assert!(why.0.contains("torch is not installed"), "{why:?}");
        let (_tmp2, numpy) = fake("echo \"ModuleNotFoundError: No module named 'numpy'\" >&2\nexit 1\n");
        let why = run(&numpy, "sh", &[]).expect("runs").expect_err("skipped");
        assert!(why.0.contains("numpy"), "{why:?}");
        let why = run(&script, "/nonexistent/python3", &[])
            .expect("runs")
            .expect_err("skipped");
        assert!(why.0.contains("/nonexistent/python3 not found"), "{why:?}");
        let why = run(&tmp.path().join("nope.py"), "sh", &[])
            .expect("runs")
            .expect_err("skipped");
        assert!(why.0.contains("nope.py not found"), "{why:?}");
    }

    #[test]
    fn a_crash_or_bad_output_is_an_error_naming_the_script() {
        let (_tmp, script) = fake("echo 'Traceback: boom' >&2\nexit 1\n");
        let err = run(&script, "sh", &[]).expect_err("a crash is an error");
        assert!(format!("{err:#}").contains("Traceback: boom"), "{err:#}");
        let (_tmp, script) = fake("echo not-json\n");
        let err = PythonReference {
            python: Path::new("sh"),
            script: &script,
            args: Vec::new(),
            threads: 1,
        }
        .json::<serde_json::Value>()
        .expect_err("bad output is an error");
        assert!(format!("{err:#}").contains("unexpected output"), "{err:#}");
    }
}
