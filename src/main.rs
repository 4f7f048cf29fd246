//! The `any4d` binary: parses the command line and calls one library function per command (`src/commands/`).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;
mod reference;

/// Keyframe-conditioned 4D mesh completion (CompletionAny4D) in Rust.
#[derive(Parser, Debug)]
#[command(name = "any4d", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    #[command(flatten)]
    limits: LimitArgs,
}

/// Size limits of the readers and generators, raised for unusually large real data (any4d_data::limits; each has a
/// hard ceiling). Given before or after the subcommand.
#[derive(clap::Args, Debug)]
struct LimitArgs {
    /// Most frames per clip (default 10000).
    #[arg(long, global = true, value_name = "N")]
    limit_frames: Option<u64>,
    /// Most vertex rows (frames × vertices) per clip (default 2^26).
    #[arg(long, global = true, value_name = "N")]
    limit_clip_vertices: Option<u64>,
    /// Most bytes read from one input file (default 4 GiB).
    #[arg(long, global = true, value_name = "BYTES")]
    limit_file_bytes: Option<u64>,
    /// Most bytes of one glTF buffer (default 1 GiB).
    #[arg(long, global = true, value_name = "BYTES")]
    limit_buffer_bytes: Option<u64>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Clip files and datasets: convert, import, synth, inspect, render.
    #[command(subcommand)]
    Data(commands::data::DataCmd),
    /// Model inspection and exchange: parameter counts, pack, export to and import from PyTorch (safetensors).
    #[command(subcommand)]
    Model(commands::model::ModelCmd),
    /// Train the VAE or the rectified flow.
    #[command(subcommand)]
    Train(commands::train::TrainCmd),
    /// Metrics, baselines and paper tables.
    #[command(subcommand)]
    Eval(commands::eval::EvalCmd),
    /// Throughput benchmarks against reference implementations.
    #[command(subcommand)]
    Bench(commands::bench::BenchCmd),
    /// The whole method on procedural clips in minutes: synth → VAE → RFs → evaluation table.
    Quickstart(commands::quickstart::QuickstartArgs),
    /// Complete a clip from its keyframes with a trained model: the in-between frames, in your coordinates.
    Complete(Box<commands::complete::CompleteArgs>),
    /// Extend keyframes to a sequence of any length (--frames) with the windowed long-horizon rollout.
    Extend(Box<commands::complete::CompleteArgs>),
    /// Play clips side by side in one self-contained HTML page (orbit, timeline, error colouring).
    View(commands::view::ViewArgs),
}

/// Every error is printed once, with its chain, and gives a non-zero exit code.
fn main() -> ExitCode {
    let cli = Cli::parse();
    let l = &cli.limits;
    if let Err(e) = any4d_data::limits::set_from_cli(
        l.limit_frames,
        l.limit_clip_vertices,
        l.limit_file_bytes,
        l.limit_buffer_bytes,
    ) {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let result = match cli.command {
        Command::Data(cmd) => commands::data::exec(cmd),
        Command::Model(cmd) => commands::model::exec(cmd),
        Command::Train(cmd) => commands::train::exec(cmd),
        Command::Eval(cmd) => commands::eval::exec(cmd),
        Command::Bench(cmd) => commands::bench::exec(cmd),
        Command::Quickstart(args) => commands::quickstart::exec(args),
        Command::Complete(args) => commands::complete::exec(*args, false),
        Command::Extend(args) => commands::complete::exec(*args, true),
        Command::View(args) => commands::view::exec(args),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap's own consistency checks over every subcommand, and no subcommand flag sharing its id or long name with
    /// a global flag (the size limits): clap accepts such a pair at build time and panics when the command runs.
    #[test]
    fn the_command_line_definition_is_consistent() {
        let cli = super::Cli::command();
        cli.clone().debug_assert();
        let globals: Vec<(String, Option<String>)> = cli
            .get_arguments()
            .filter(|a| a.is_global_set())
            .map(|a| (a.get_id().to_string(), a.get_long().map(str::to_string)))
            .collect();
        assert!(globals.len() >= 4, "{globals:?}");
        fn walk(cmd: &clap::Command, path: &str, globals: &[(String, Option<String>)], clashes: &mut Vec<String>) {
            for a in cmd.get_arguments().filter(|a| !a.is_global_set()) {
                let (id, long) = (a.get_id().to_string(), a.get_long().map(str::to_string));
                if globals
                    .iter()
                    .any(|(g, gl)| *g == id || (long.is_some() && *gl == long))
                {
                    clashes.push(format!("{path} --{}", long.unwrap_or(id)));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), globals, clashes);
            }
        }
        let mut clashes = Vec::new();
        walk(&cli, "any4d", &globals, &mut clashes);
        assert!(
            clashes.is_empty(),
            "subcommand flags that shadow a global flag: {clashes:?}"
        );
    }
}
