//! Training loops, run folders and the `any4d` CLI (the only place that parses arguments).

pub mod cli;
