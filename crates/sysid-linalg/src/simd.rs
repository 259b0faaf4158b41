//! Run-time selection of the vector instruction set for a hot kernel.
//!
//! [`dispatch`] runs a [`Kernel`] from a function compiled for AVX-512 or AVX2+FMA when
//! the CPU has them; the kernel (and whatever the compiler inlines into it, such as
//! the methods of a generic model) is then compiled for that instruction set too. Without
//! them, it runs as compiled for the baseline target.
//!
//! Rust never contracts `a * b + c` into a fused operation on its own, and only explicit
//! `mul_add` (correctly rounded on every path) fuses, so every path computes the same
//! bits: a seed reproduces a run on any x86-64 machine, and a filter gives the same
//! numbers with and without the wide instructions.
//!
//! For a kernel to benefit, the work it calls has to be compiled into it: generic
//! code, `#[inline]` functions of other crates and `#[inline(always)]` helpers are;
//! a call to a function the compiler keeps out of line runs that function's baseline
//! copy. A closure body passed through is not re-compiled either (hence the trait).
//!
//! # Example
//! ```
//! use sysid_linalg::simd::{Kernel, dispatch};
//! struct SumOfSquares<'a>(&'a [f64]);
//! impl Kernel for SumOfSquares<'_> {
//!     type Output = f64;
//!     #[inline(always)]
//!     fn run(self) -> f64 {
//!         sysid_linalg::dot(self.0, self.0)
//!     }
//! }
//! assert_eq!(dispatch(SumOfSquares(&[3.0, 4.0])), 25.0);
//! ```

/// A hot piece of work. Implement [`run`](Kernel::run) with `#[inline(always)]` so that
/// it is compiled into each instruction-set variant of [`dispatch`] (closures cannot be
/// forced inline, which is why this is a trait).
pub trait Kernel {
    /// What the work returns.
    type Output;
    /// Does the work.
    fn run(self) -> Self::Output;
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
fn call_avx512<K: Kernel>(f: K) -> K::Output {
    f.run()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn call_avx2<K: Kernel>(f: K) -> K::Output {
    f.run()
}

/// Runs `f` compiled for the widest vector instruction set the CPU supports.
#[inline(always)]
pub fn dispatch<K: Kernel>(f: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports the enabled features, checked just above.
            return unsafe { call_avx512(f) };
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: as above.
            return unsafe { call_avx2(f) };
        }
    }
    f.run()
}
