//! Fuzz target: glTF JSON or GLB bytes (buffers inside the file only) through the reader and the baker.
#![no_main]

use std::path::Path;

use any4d_data::formats::PANIC_FIELD;
use any4d_data::formats::gltf::{ExternalBuffers, GltfReadOptions, read_gltf_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let name = if data.starts_with(b"glTF") {
        "fuzz.glb"
    } else {
        "fuzz.gltf"
    };
    let read = read_gltf_bytes(
        data,
        Path::new(name),
        &GltfReadOptions::default(),
        &ExternalBuffers::Refuse,
    );
    // The reader turns a panic into an error; for the fuzzer that is still a crash.
    if let Err(e) = read {
        assert_ne!(e.field, PANIC_FIELD, "{e}");
    }
});
