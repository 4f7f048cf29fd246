//! `any4d model …` (owner: see ARCHITECTURE.md). Parses arguments, calls the library.

use std::process::ExitCode;

use clap::{Args, Subcommand};

#[derive(Subcommand, Debug)]
pub enum ModelCmd {
    /// Placeholder until the subcommands land.
    Todo,
}

#[derive(Args, Debug)]
pub struct BenchArgs {}

pub fn run(cmd: ModelCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        ModelCmd::Todo => anyhow::bail!("not implemented yet"),
    }
}

pub fn bench(_args: BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("not implemented yet")
}
