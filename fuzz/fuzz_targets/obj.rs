//! Fuzz target: one OBJ frame through the parser.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = any4d_data::formats::obj::parse_obj(text, Path::new("fuzz.obj"));
    }
});
