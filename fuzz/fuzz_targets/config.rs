//! Fuzz target: one run config (TOML text) through the strict loader, as `train`, `model summary`, `bench` and
//! `eval` read it: `extends` resolves against an empty set of presets (so only the text itself is read), then
//! the VAE/RF parse and every range check. It must give a config or a clean error, never panic or allocate from a
//! size the text claims (model sizes are refused above the parameter limit before anything is built).
#![no_main]

use std::path::Path;

use any4d_train::config::{Embedded, RunConfig, resolve};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let path = Path::new("fuzz.toml");
        if let Ok(table) = resolve::resolve_text(&Embedded(&[]), text, path) {
            let _ = RunConfig::from_table(table, path);
        }
    }
});
