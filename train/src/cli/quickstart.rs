//! `any4d quickstart`: the README's first command.

use std::process::ExitCode;

use clap::Args;

#[derive(Args, Debug)]
pub struct QuickstartArgs {
    /// Output folder for the dataset, runs, table and pictures.
    #[arg(long, default_value = "runs/quickstart")]
    pub out: std::path::PathBuf,
}

pub fn run(_args: QuickstartArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("not implemented yet")
}
