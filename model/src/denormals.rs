//! Subnormal floats on the CPU (docs/method.md §10): an f32 below 2⁻¹²⁶ ≈ 1.2e-38 in magnitude costs x86 cores a
//! microcode assist in every operation that reads or writes one, and training makes them as it learns.
//! [`set_flush_denormals`] sets the calling thread's flush-to-zero and denormals-are-zero modes: subnormal results become
//! 0 and subnormal inputs read as 0; normal floats are untouched.

/// Flush-to-zero (bit 15) and denormals-are-zero (bit 6) of the x86 MXCSR register.
#[cfg(target_arch = "x86_64")]
const MXCSR_FTZ_DAZ: u32 = (1 << 15) | (1 << 6);

/// Sets (`on`) or clears flush-to-zero and denormals-are-zero on the calling thread (x86_64: MXCSR FTZ and DAZ;
/// aarch64: FPCR.FZ, which flushes inputs too). Returns whether the architecture has the modes (false elsewhere:
/// nothing changes). The mode is per thread, and a thread started later inherits its parent's: the training loop sets
/// it on its own thread and, by `broadcast`, on every thread of its rayon pools, and clears it again when it ends.
#[allow(unsafe_code)]
pub fn set_flush_denormals(on: bool) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let mut csr: u32 = 0;
        // SAFETY: stmxcsr / ldmxcsr read and write the calling thread's SSE control register through a pointer to a
        // live local u32; only the FTZ and DAZ bits change, exception masks and rounding stay as they were. Rust's
        // documentation calls running Rust code with these modes changed undefined behaviour, because the compiler
        // may evaluate floating-point expressions at compile time under the default modes: such an expression can
        // then keep a subnormal value that the same operation at run time would have flushed. That is the only
        // difference, and it is the one the modes are set for; the choice is deliberate, as in TensorFlow's and
        // XLA's CPU thread pools (docs/method.md §10).
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
            csr = if on { csr | MXCSR_FTZ_DAZ } else { csr & !MXCSR_FTZ_DAZ };
            std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, preserves_flags, readonly));
        }
        true
    }
    #[cfg(target_arch = "aarch64")]
    {
        const FZ: u64 = 1 << 24;
        let mut fpcr: u64;
        // SAFETY: mrs / msr read and write the calling thread's floating-point control register; only FZ changes,
        // exception enables and rounding stay as they were (the x86 comment above says what the mode changes).
        unsafe {
            std::arch::asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack, preserves_flags));
            fpcr = if on { fpcr | FZ } else { fpcr & !FZ };
            std::arch::asm!("msr fpcr, {}", in(reg) fpcr, options(nomem, nostack, preserves_flags));
        }
        true
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        let _ = on;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hint::black_box;

    /// (subnormal result of a product of normals, a subnormal input scaled into the normal range)
    fn probe() -> (f32, f32) {
        (
            black_box(1.0e-30_f32) * black_box(1.0e-10_f32),
            black_box(1.0e-40_f32) * black_box(1.0e30_f32),
        )
    }

    /// Flushing zeroes subnormal results and reads subnormal inputs as 0 on the flushing thread and the threads it
    /// starts, not on others; clearing restores both.
    #[test]
    fn flushing_zeroes_subnormals_on_its_thread_until_cleared() {
        assert!(black_box(1.0e-40_f32).is_subnormal());
        let (result, input) = std::thread::spawn(probe).join().unwrap();
        assert!(
            result.is_subnormal() && input > 1.0e-11,
            "default mode keeps subnormals: {result:e} {input:e}"
        );
        let (has, flushed, child, cleared) = std::thread::spawn(|| {
            let has = set_flush_denormals(true);
            let flushed = probe();
            let child = std::thread::spawn(probe).join().unwrap();
            set_flush_denormals(false);
            (has, flushed, child, probe())
        })
        .join()
        .unwrap();
        if has {
            assert_eq!(flushed, (0.0, 0.0), "flush to zero, denormals are zero");
            assert_eq!(
                child,
                (0.0, 0.0),
                "a thread started by a flushing thread inherits the mode"
            );
        }
        assert!(cleared.0.is_subnormal() && cleared.1 > 1.0e-11, "cleared: {cleared:?}");
        let (result, _) = std::thread::spawn(probe).join().unwrap();
        assert!(result.is_subnormal(), "another thread never flushed");
    }
}
