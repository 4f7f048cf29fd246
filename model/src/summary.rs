//! Parameter counts of a network per top-level submodule (checks docs/method.md §4.3 "≈ 78M trainable"; used by
//! `any4d model summary` and `any4d bench model`).

use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::*;

/// Name of the last row of [`param_report`].
/// The most parameters a config may ask for (2³¹ ≈ 2.1 billion, 8.6 GB in f32): a bound checked before any weight is
/// allocated, so a mistyped size (`width = 1e6`) is an error naming the field instead of an allocation failure.
pub const MAX_PARAMS: u128 = 1 << 31;

/// The error of a config whose parameter estimate exceeds [`MAX_PARAMS`].
pub fn check_param_estimate(what: &str, estimate: u128) -> Result<(), String> {
    if estimate > MAX_PARAMS {
        return Err(format!(
            "{what} ask for about {estimate} parameters ({:.1} GB in f32), over the {MAX_PARAMS} this build allows",
            estimate as f64 * 4e-9
        ));
    }
    Ok(())
}

/// Memory of this machine in bytes (`MemTotal` of `/proc/meminfo`), `None` where it cannot be read.
pub fn host_memory_bytes() -> Option<u128> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The error of a micro-batch whose activation estimate exceeds `limit` bytes (the host's memory for CPU
/// backends): the estimate, the limit and the remedy.
pub fn check_activation_estimate(what: &str, estimate: u128, limit: u128) -> Result<(), String> {
    if estimate > limit {
        let gib = |b: u128| b as f64 / (1u128 << 30) as f64;
        return Err(format!(
            "{what} keeps about {:.1} GiB of activations for the backward pass, more than the {:.1} GiB available: \
             lower train.micro_batch (gradient accumulation keeps train.batch_size)",
            gib(estimate),
            gib(limit)
        ));
    }
    Ok(())
}

pub const TOTAL: &str = "total";

/// One float parameter: the names of the modules and fields leading to it (`["blocks", "0", "qkv", "weight"]`)
/// and its shape.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NamedParam {
    /// Module and field names from the root down to the parameter.
    pub path: Vec<String>,
    /// Its shape.
    pub shape: Vec<usize>,
}

impl NamedParam {
    /// Number of elements.
    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }
}

/// Every float parameter of `module`, in visiting (declaration) order.
pub fn named_params<M: Module>(module: &M) -> Vec<NamedParam> {
    #[derive(Default)]
    struct Collect {
        path: Vec<String>,
        params: Vec<NamedParam>,
    }
    impl ModuleVisitor for Collect {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.params.push(NamedParam {
                path: self.path.clone(),
                shape: param.lazy_shape().dims::<D>().to_vec(),
            });
        }
    }
    let mut c = Collect::default();
    module.visit(&mut c);
    c.params
}

/// Float parameter counts per top-level submodule, in declaration order, followed by `("total", sum)`.
/// Vectors of blocks count as one submodule (e.g. `blocks`).
pub fn param_report<M: Module>(module: &M) -> Vec<(String, usize)> {
    let mut rows: Vec<(String, usize)> = Vec::new();
    for p in named_params(module) {
        let name = p.path.first().cloned().unwrap_or_else(|| "(root)".to_string());
        match rows.iter_mut().find(|(n, _)| *n == name) {
            Some((_, total)) => *total += p.numel(),
            None => rows.push((name, p.numel())),
        }
    }
    let total = rows.iter().map(|(_, n)| n).sum();
    rows.push((TOTAL.to_string(), total));
    rows
}

/// Renders a report as aligned text lines (name, count, share of the total).
pub fn format_report(title: &str, rows: &[(String, usize)]) -> String {
    let total = rows.iter().find(|(n, _)| n == TOTAL).map_or(0, |(_, n)| *n).max(1);
    let width = rows.iter().map(|(n, _)| n.len()).max().unwrap_or(0).max(8);
    let mut out = format!("{title}\n");
    for (name, count) in rows {
        let share = 100.0 * *count as f64 / total as f64;
        out.push_str(&format!("  {name:<width$}  {count:>12}  {share:6.2}%\n"));
    }
    out
}
