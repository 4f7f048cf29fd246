//! `any4d bench …`: each benchmark lives with its subcommand group and runs its reference in the same process or
//! script, reporting ratios.

use std::process::ExitCode;

use clap::Subcommand;

#[derive(Subcommand, Debug)]
pub enum BenchCmd {
    /// Import + normalise + FPS throughput against the Python reference.
    Data(super::data::BenchArgs),
    /// VAE encode+decode and RF forward+backward time per clip.
    Model(super::model::BenchArgs),
    /// Training steps/s for a preset: RF presets on random latents with model FLOP/s, VAE presets on a store.
    Train(super::bench_train::BenchArgs),
    /// Metric throughput against the numpy/scipy reference.
    Metrics(super::eval::BenchArgs),
}

pub fn run(cmd: BenchCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        BenchCmd::Data(args) => super::data::bench(args),
        BenchCmd::Model(args) => super::model::bench(args),
        BenchCmd::Train(args) => super::bench_train::bench(args),
        BenchCmd::Metrics(args) => super::eval::bench(args),
    }
}
