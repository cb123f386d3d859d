//! The processor's vector state between faer's kernels and the scalar code around them.
//!
//! faer's matrix products (its `gemm` kernels, AVX-512 or AVX2 on x86-64) return with the upper
//! halves of the vector registers still set. Until a `vzeroupper` clears them, the processor
//! saves or restores those halves at every switch between legacy-SSE code (vmt's own, built for
//! baseline x86-64) and VEX code (libm's `sin`, `cos`, `exp`, `log`, which glibc dispatches to its
//! FMA versions): tens of cycles each way, twice per libm call. Measured on the development
//! machine (Xeon, 2 cores): one `f64::sin_cos` took 16 ns on a clean state and 190 ns after one
//! faer `matmul`; the cyclic lead's scan (`vmt diagnose`, 1 724 periods × 2 × 19 910 `sin_cos`)
//! spent 6.5 s of CPU in its phase check alone before the state was cleared, 0.55 s after.
//! Clearing changes no result: the upper halves are dead at that point (no caller keeps a vector
//! value in a register across a function call), and the arithmetic is the same instructions.
//!
//! [`clear_upper_state`] is called at the start of every loop that calls libm once or more per
//! sample (signature columns, free vibrations, the loop's lag filters, periodograms): on the
//! thread that runs it, after whatever faer did on that thread before.

/// Clears the upper halves of the vector registers (`vzeroupper`) on an x86-64 processor with
/// AVX, so that the libm calls that follow run without state transitions (module doc); nothing on
/// other processors. Costs a few cycles (the feature test is a cached load).
#[inline]
pub fn clear_upper_state() {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: `vzeroupper` needs AVX, which the processor has (tested just above).
        unsafe { zero_upper() }
    }
}

/// `vzeroupper` ([`clear_upper_state`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn zero_upper() {
    std::arch::x86_64::_mm256_zeroupper();
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::matmul::matmul;
    use faer::{Accum, Mat, Par};

    /// The sum of sin θ + cos θ over a fixed set of angles.
    fn waves() -> f64 {
        (0..4000).map(|i| (0.37 * f64::from(i)).sin_cos()).map(|(s, c)| s + c).sum()
    }

    /// After a faer product, clearing the state leaves libm's results bit for bit as they were.
    #[test]
    fn clearing_after_a_product_keeps_the_bits() {
        let before = waves();
        let a = Mat::<f64>::from_fn(96, 40, |i, j| (i as f64 - j as f64).sin());
        let b = Mat::<f64>::from_fn(40, 24, |i, j| (i * j) as f64 / 7.0);
        let mut c = Mat::<f64>::zeros(96, 24);
        matmul(c.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, Par::Seq);
        let dirty = waves();
        clear_upper_state();
        let clean = waves();
        assert_eq!(before.to_bits(), dirty.to_bits());
        assert_eq!(before.to_bits(), clean.to_bits());
        assert!(c[(95, 23)].is_finite());
    }
}
