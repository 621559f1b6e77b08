//! One kernel body, two builds: for the x86-64 baseline (SSE2) and with AVX2 + FMA enabled,
//! chosen at run time ([`Simd::detect`]). With AVX2 the compiler evaluates the same loops 8
//! lanes wide. No kernel calls `mul_add` (and Rust never fuses a multiply and an add by
//! itself), so both builds compute bit-identical results; each kernel's tests compare it with
//! a per-pixel reference.

/// Which build of a kernel runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Simd {
    /// The x86-64 baseline (or any other architecture).
    Baseline,
    /// AVX2 + FMA (x86-64 only, chosen at run time when the CPU has them).
    Avx2,
}

impl Simd {
    /// The widest build this CPU runs.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                return Self::Avx2;
            }
        }
        Self::Baseline
    }
}

/// `fn $name(simd, args…)`: runs `$generic(args…)` (an `#[inline(always)]` body) from a
/// baseline or an AVX2 + FMA function. Both are separate non-inlined functions whose slice
/// arguments the compiler knows do not alias. Const generic parameters, if given
/// (`$generic<const N: usize, …>`), become the kernel's own.
macro_rules! simd_kernel {
    (
        $name:ident,
        $avx2:ident,
        $generic:ident $(<$(const $g:ident: $gt:ty),+>)?,
        ($($arg:ident: $ty:ty),*) $(-> $ret:ty)?
    ) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        #[allow(clippy::too_many_arguments)]
        unsafe fn $avx2 $(<$(const $g: $gt),+>)? ($($arg: $ty),*) $(-> $ret)? {
            $generic $(::<$($g),+>)? ($($arg),*)
        }

        #[inline(never)]
        #[allow(clippy::too_many_arguments)]
        fn $name $(<$(const $g: $gt),+>)? (simd: $crate::simd::Simd, $($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                if simd == $crate::simd::Simd::Avx2 {
                    // SAFETY: `Simd::Avx2` is only chosen when the CPU has AVX2 and FMA.
                    return unsafe { $avx2 $(::<$($g),+>)? ($($arg),*) };
                }
            }
            let _ = simd;
            $generic $(::<$($g),+>)? ($($arg),*)
        }
    };
}
pub(crate) use simd_kernel;
