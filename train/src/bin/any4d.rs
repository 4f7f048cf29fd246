//! The one CLI binary: parses arguments and calls library functions (see `any4d_train::cli`).

fn main() -> std::process::ExitCode {
    any4d_train::cli::main()
}
