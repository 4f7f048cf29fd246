//! The command tree of `any4d`, one file per subcommand group (cargo's `src/bin/cargo/commands/` layout): each
//! defines its clap arguments and an `exec` that turns them into a library call; nothing here computes.

use std::str::FromStr;

use any4d_train::loop_common::StopFlag;
use clap::builder::{PossibleValuesParser, TypedValueParser};

pub mod bench;
pub mod complete;
pub mod data;
pub mod eval;
pub mod model;
pub mod quickstart;
pub mod scene;
pub mod timing;
pub mod train;
pub mod view;

/// A clap parser for a library enum with `Display` + `FromStr` (so the libraries need no clap): `--help` lists
/// `all`, and the value is parsed by the enum itself.
pub fn enum_parser<T>(all: &[T]) -> impl TypedValueParser<Value = T>
where
    T: FromStr<Err = String> + ToString + Clone + Send + Sync + 'static,
{
    let names: Vec<String> = all.iter().map(ToString::to_string).collect();
    PossibleValuesParser::new(names).try_map(|name| T::from_str(&name))
}

/// A stop flag that Ctrl-C sets: the training loops save a checkpoint and return (once per process).
pub fn stop_on_ctrl_c() -> anyhow::Result<StopFlag> {
    let stop = StopFlag::new();
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.request())
        .map_err(|e| anyhow::anyhow!("cannot install the Ctrl-C handler: {e}"))?;
    Ok(stop)
}
