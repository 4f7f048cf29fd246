//! `any4d eval …` (owner: see ARCHITECTURE.md). Parses arguments, calls the library.

use std::process::ExitCode;

use clap::{Args, Subcommand};

#[derive(Subcommand, Debug)]
pub enum EvalCmd {
    /// Placeholder until the subcommands land.
    Todo,
}

#[derive(Args, Debug)]
pub struct BenchArgs {}

pub fn run(cmd: EvalCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        EvalCmd::Todo => anyhow::bail!("not implemented yet"),
    }
}

pub fn bench(_args: BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("not implemented yet")
}
