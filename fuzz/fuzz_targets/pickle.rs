//! Fuzz target: DyMesh `.bin` bytes through the restricted unpickler and the clip checks.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Ok or a clean error; a panic, an abort or a hang is a finding.
    let _ = any4d_data::formats::dymesh_bin::read_bin_bytes(data, "fuzz.bin");
});
