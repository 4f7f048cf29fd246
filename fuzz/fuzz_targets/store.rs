//! Fuzz target: a store's `clips.bin`: open it (header, table, trailer), then decode every clip.
#![no_main]

use std::sync::OnceLock;

use any4d_data::store::{CLIPS_FILE, Store};
use libfuzzer_sys::fuzz_target;

fn folder() -> &'static tempfile::TempDir {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary folder"))
}

fuzz_target!(|data: &[u8]| {
    let dir = folder().path();
    std::fs::write(dir.join(CLIPS_FILE), data).expect("writing the input");
    if let Ok(store) = Store::open(dir) {
        for i in 0..store.len() {
            let _ = store.get(i);
        }
    }
});
