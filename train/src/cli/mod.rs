//! `any4d` command line: one subcommand group per crate; each group lives in its own file and only parses
//! arguments before calling a library function.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub mod bench;
pub mod bench_formats;
pub mod bench_train;
pub mod data;
pub mod eval;
pub mod eval_run;
pub mod model;
pub mod quickstart;
pub mod train;

/// Keyframe-conditioned 4D mesh completion (CompletionAny4D) in Rust.
#[derive(Parser, Debug)]
#[command(name = "any4d", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Clip files and datasets: convert, import, synth, inspect, render.
    #[command(subcommand)]
    Data(data::DataCmd),
    /// Model inspection: parameter counts.
    #[command(subcommand)]
    Model(model::ModelCmd),
    /// Train the VAE or the rectified flow.
    #[command(subcommand)]
    Train(train::TrainCmd),
    /// Metrics, baselines and paper tables.
    #[command(subcommand)]
    Eval(eval::EvalCmd),
    /// Throughput benchmarks against reference implementations.
    #[command(subcommand)]
    Bench(bench::BenchCmd),
    /// The whole method on procedural clips in minutes: synth → VAE → RFs → evaluation table.
    Quickstart(quickstart::QuickstartArgs),
}

/// Entry point of the binary: every error is printed once, with its chain, and gives a non-zero exit code.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Data(cmd) => data::run(cmd),
        Command::Model(cmd) => model::run(cmd),
        Command::Train(cmd) => train::run(cmd),
        Command::Eval(cmd) => eval::run(cmd),
        Command::Bench(cmd) => bench::run(cmd),
        Command::Quickstart(args) => quickstart::run(args),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
