//! `any4d data …` (owner: see ARCHITECTURE.md). Parses arguments, calls the library.

use std::process::ExitCode;

use clap::{Args, Subcommand};

#[derive(Subcommand, Debug)]
pub enum DataCmd {
    /// Placeholder until the subcommands land.
    Todo,
}

#[derive(Args, Debug)]
pub struct BenchArgs {}

pub fn run(cmd: DataCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        DataCmd::Todo => anyhow::bail!("not implemented yet"),
    }
}

pub fn bench(_args: BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("not implemented yet")
}
