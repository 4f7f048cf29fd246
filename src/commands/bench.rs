//! `any4d bench …`: each benchmark's measurement lives in the crate it measures (`any4d_data::bench`,
//! `any4d_model::bench`, `any4d_train::bench`, `any4d_eval::bench`); its arguments and report live with its
//! subcommand group here, and its Python reference runs through `crate::reference`.

use std::process::ExitCode;

use clap::Subcommand;

#[derive(Subcommand, Debug)]
pub enum BenchCmd {
    /// Import + normalise + FPS throughput against the Python reference.
    Data(super::data::BenchArgs),
    /// VAE encode+decode and RF forward+backward time per clip.
    Model(super::model::BenchArgs),
    /// Training steps/s for a preset: RF presets on random latents with model FLOP/s, VAE presets on a store.
    Train(super::train::BenchArgs),
    /// Metric throughput against the numpy/scipy reference.
    Metrics(super::eval::BenchArgs),
    /// Wall time of `any4d complete` for one 16-frame clip per vertex count (median over repetitions).
    Complete(super::complete::BenchArgs),
    /// P-Table 4 timing (encode → midpoint sampling → decode, 16 and 31 frames) of ours at a config's size with
    /// freshly initialised weights, on any backend: no trained run needed.
    Sample(super::timing::SampleBenchArgs),
}

pub fn exec(cmd: BenchCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        BenchCmd::Data(args) => super::data::bench(args),
        BenchCmd::Model(args) => super::model::bench(args),
        BenchCmd::Train(args) => super::train::bench(args),
        BenchCmd::Metrics(args) => super::eval::bench(args),
        BenchCmd::Complete(args) => super::complete::bench(args),
        BenchCmd::Sample(args) => super::timing::bench_sample(args),
    }
}
