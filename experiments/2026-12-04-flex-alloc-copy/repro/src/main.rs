//! Reproducer: `cubecl_environment::bytes::Bytes::from_bytes_vec` copies every buffer into a new allocation, because
//! `from_elems::<u8>` records the allocation's alignment as `align_of::<u8>() = 1`, so
//! `try_enforce_runtime_align(MAX_ALIGN = 16)` always reallocates, even when the Vec's pointer is already
//! 16-byte aligned (glibc malloc returns 16-aligned blocks). burn-flex's `FlexTensor::empty` (hence `zeros` and the
//! output of every op that allocates, e.g. matmul) goes through it, so each allocation is made twice and copied once.
use std::hint::black_box;
use std::time::Instant;

use burn::prelude::{Device, Tensor};
use cubecl_environment::bytes::Bytes;

fn main() {
    let n = 64 << 20; // 64 MiB
    let v = vec![0u8; n];
    let before = v.as_ptr() as usize;
    let bytes = Bytes::from_bytes_vec(v);
    let after = bytes.as_ptr() as usize;
    println!(
        "Vec buffer at {before:#x} (16-byte aligned: {}); Bytes at {after:#x}: {}",
        before % 16 == 0,
        if after == before { "same buffer, no copy" } else { "a new buffer: reallocated and copied" }
    );

    let reps = 20;
    let t = Instant::now();
    for _ in 0..reps {
        black_box(vec![0u8; n]);
    }
    let vec_only = t.elapsed().as_secs_f64() / reps as f64;
    let t = Instant::now();
    for _ in 0..reps {
        black_box(Bytes::from_bytes_vec(vec![0u8; n]));
    }
    let through_bytes = t.elapsed().as_secs_f64() / reps as f64;
    println!(
        "vec![0u8; 64 MiB]: {:.2} ms; Bytes::from_bytes_vec(vec![0u8; 64 MiB]): {:.2} ms ({:.1}x)",
        vec_only * 1e3,
        through_bytes * 1e3,
        through_bytes / vec_only
    );

    let device = Device::flex();
    let t = Instant::now();
    for _ in 0..reps {
        black_box(Tensor::<2>::zeros([4096, 4096], &device)); // 64 MiB of f32 through FlexTensor::empty
    }
    println!(
        "burn-flex Tensor::zeros([4096, 4096]): {:.2} ms",
        t.elapsed().as_secs_f64() / reps as f64 * 1e3
    );
}
