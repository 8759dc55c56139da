//! IEEE arithmetic for code that needs subnormal numbers.
//!
//! Renderers run their worker threads with subnormals flushed to zero
//! (x86's FTZ and DAZ, AArch64's FZ): Mitsuba's scene loading does, and a
//! thread inherits the mode of the thread that spawned it. The rigorous
//! solver's eigen decompositions and layer products do not survive that
//! mode: built on Mitsuba's loading threads, the compact disc's table came
//! out all zeros, in 36 s instead of 6 (every solve non-finite). A
//! `StandardFloats` guard sets round-to-nearest with subnormals kept, and
//! puts the caller's mode back when dropped.

/// The floating-point mode of this thread set to IEEE's default until the
/// guard is dropped (guards nest).
#[must_use = "the standard mode lasts as long as the guard"]
pub struct StandardFloats {
    #[cfg_attr(
        not(any(target_arch = "x86_64", target_arch = "aarch64")),
        allow(dead_code)
    )]
    saved: u64,
}

#[cfg(target_arch = "x86_64")]
mod arch {
    use std::arch::asm;

    /// MXCSR: flush-to-zero (bit 15), denormals-are-zero (bit 6) and the
    /// rounding mode (bits 13-14, 0 = nearest).
    const NON_STANDARD: u32 = (1 << 15) | (1 << 6) | (3 << 13);

    pub fn read() -> u64 {
        let mut csr: u32 = 0;
        // SAFETY: stores MXCSR into a local.
        unsafe { asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack)) };
        csr as u64
    }

    pub fn write(mode: u64) {
        let csr = mode as u32;
        // SAFETY: loads a value read from MXCSR, or one with only the mode
        // bits above cleared (no exception is unmasked).
        unsafe { asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack)) };
    }

    pub fn standard(mode: u64) -> u64 {
        mode & !(NON_STANDARD as u64)
    }
}

#[cfg(target_arch = "aarch64")]
mod arch {
    use std::arch::asm;

    /// FPCR: flush-to-zero (bit 24), half-precision flush (bit 19) and the
    /// rounding mode (bits 22-23, 0 = nearest).
    const NON_STANDARD: u64 = (1 << 24) | (1 << 19) | (3 << 22);

    pub fn read() -> u64 {
        let fpcr: u64;
        // SAFETY: reads the floating-point control register.
        unsafe { asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack)) };
        fpcr
    }

    pub fn write(mode: u64) {
        // SAFETY: writes a value read from FPCR, or one with only the mode
        // bits above cleared (no trap is enabled).
        unsafe { asm!("msr fpcr, {}", in(reg) mode, options(nomem, nostack)) };
    }

    pub fn standard(mode: u64) -> u64 {
        mode & !NON_STANDARD
    }
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
mod arch {
    pub fn read() -> u64 {
        0
    }
    pub fn write(_: u64) {}
    pub fn standard(mode: u64) -> u64 {
        mode
    }
}

impl StandardFloats {
    pub fn enter() -> StandardFloats {
        let saved = arch::read();
        let standard = arch::standard(saved);
        if standard != saved {
            arch::write(standard);
        }
        StandardFloats { saved }
    }
}

impl Drop for StandardFloats {
    fn drop(&mut self) {
        if arch::read() != self.saved {
            arch::write(self.saved);
        }
    }
}

/// Test helper: run `f` with subnormals flushed to zero (as a renderer's
/// threads do), the thread's mode restored afterwards.
#[cfg(test)]
pub fn with_flushed_subnormals<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    let flushed = |m: u64| m | (1 << 15) | (1 << 6);
    #[cfg(target_arch = "aarch64")]
    let flushed = |m: u64| m | (1 << 24);
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let flushed = |m: u64| m;
    let saved = arch::read();
    arch::write(flushed(saved));
    let out = f();
    arch::write(saved);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The smallest normal f64 halved: a subnormal, unless flushed.
    fn half_of_smallest_normal() -> f64 {
        std::hint::black_box(f64::MIN_POSITIVE) * std::hint::black_box(0.5)
    }

    #[test]
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    fn the_guard_keeps_subnormals_and_restores_the_callers_mode() {
        assert!(half_of_smallest_normal() > 0.0);
        with_flushed_subnormals(|| {
            assert_eq!(half_of_smallest_normal(), 0.0, "the helper flushes");
            {
                let _ieee = StandardFloats::enter();
                assert!(half_of_smallest_normal() > 0.0, "the guard keeps them");
                let _nested = StandardFloats::enter();
                assert!(half_of_smallest_normal() > 0.0);
            }
            assert_eq!(half_of_smallest_normal(), 0.0, "the caller's mode is back");
        });
        assert!(half_of_smallest_normal() > 0.0);
    }
}
