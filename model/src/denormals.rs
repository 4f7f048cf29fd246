//! Subnormal floats on the CPU (docs/method.md §10): an f32 below 2⁻¹²⁶ ≈ 1.2e-38 in magnitude costs x86 cores a
//! microcode assist in every operation that reads or writes one, and training makes them as it learns.
//! [`flush_denormals`] sets the calling thread's flush-to-zero and denormals-are-zero modes: subnormal results become
//! 0 and subnormal inputs read as 0; normal floats are untouched.

/// Flush-to-zero (bit 15) and denormals-are-zero (bit 6) of the x86 MXCSR register.
#[cfg(target_arch = "x86_64")]
const MXCSR_FTZ_DAZ: u32 = (1 << 15) | (1 << 6);

/// Sets flush-to-zero and denormals-are-zero on the calling thread (x86_64: MXCSR; aarch64: FPCR.FZ). Returns
/// whether the architecture has the modes (false elsewhere: nothing is changed). Every thread that computes must
/// call it: a rayon pool's `start_handler`, the thread that runs the optimiser.
#[allow(unsafe_code)]
pub fn flush_denormals() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let mut csr: u32 = 0;
        // SAFETY: stmxcsr / ldmxcsr read and write the calling thread's SSE control register through a pointer to a
        // live local u32. Only the FTZ and DAZ bits are added: exception masks and rounding stay as they were, so
        // no operation traps or rounds differently; results that would be subnormal become zero instead.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
            csr |= MXCSR_FTZ_DAZ;
            std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, preserves_flags));
        }
        true
    }
    #[cfg(target_arch = "aarch64")]
    {
        let mut fpcr: u64;
        // SAFETY: mrs / msr read and write the calling thread's floating-point control register; only FZ (bit 24)
        // is set, exception enables and rounding mode stay as they were.
        unsafe {
            std::arch::asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack, preserves_flags));
            fpcr |= 1 << 24;
            std::arch::asm!("msr fpcr, {}", in(reg) fpcr, options(nomem, nostack, preserves_flags));
        }
        true
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a thread that flushes, a product with a subnormal result is 0, and a subnormal input reads as 0 (x86);
    /// a thread that does not keeps both, so the mode is per thread and off by default.
    #[test]
    fn flushing_zeroes_subnormal_results_on_this_thread_only() {
        let tiny = std::hint::black_box(1.0e-30_f32);
        let scale = std::hint::black_box(1.0e-10_f32);
        let sub = std::hint::black_box(1.0e-40_f32);
        assert!(sub.is_subnormal());
        let one = std::hint::black_box(1.0_f32);
        let before = std::thread::spawn(move || (tiny * scale, sub * one)).join().unwrap();
        assert!(
            before.0.is_subnormal() && before.1 == sub,
            "default mode keeps subnormals: {before:?}"
        );
        let after = std::thread::spawn(move || {
            let has = flush_denormals();
            (
                has,
                std::hint::black_box(tiny) * std::hint::black_box(scale),
                std::hint::black_box(sub) * one,
            )
        })
        .join()
        .unwrap();
        if after.0 {
            assert_eq!(after.1, 0.0, "flush to zero");
            if cfg!(target_arch = "x86_64") {
                assert_eq!(after.2, 0.0, "denormals are zero");
            }
        }
    }
}
