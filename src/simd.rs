//! One kernel body, three builds: for the x86-64 baseline (SSE2), with AVX2 + FMA enabled and
//! with AVX-512 enabled, chosen at run time ([`Simd::detect`]). With AVX2 the compiler evaluates
//! the same loops 8 lanes wide; AVX-512 adds wider registers, twice as many of them, and masked
//! and mixed-width instructions. No kernel calls `mul_add` (and Rust never fuses a multiply and
//! an add by itself), so all builds compute bit-identical results; each kernel's tests compare
//! it with a per-pixel reference.
//!
//! `OCCMASK_SIMD` (`baseline`, `avx2` or `avx512`) caps the build that runs, to compare builds
//! or to rule one out; `.ci/run` runs the unit tests under each cap, so every build of every
//! kernel is tested on the CI machine.

use std::sync::OnceLock;

use crate::error::{Error, Result};

/// The environment variable that caps the kernels' build ([`Simd::detect`]).
pub const SIMD_ENV_VAR: &str = "OCCMASK_SIMD";

/// Which build of a kernel runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Simd {
    /// The x86-64 baseline (or any other architecture).
    Baseline,
    /// AVX2 + FMA (x86-64 only, chosen at run time when the CPU has them).
    Avx2,
    /// AVX-512 (F, BW, DQ, VL) with AVX2 + FMA: x86-64-v4's vector set.
    Avx512,
}

impl Simd {
    /// Every build, narrowest first.
    pub const ALL: [Self; 3] = [Self::Baseline, Self::Avx2, Self::Avx512];

    /// Every build this CPU runs, narrowest first (what a kernel's tests compare).
    pub fn available() -> impl Iterator<Item = Self> {
        let widest = Self::cpu();
        Self::ALL.into_iter().filter(move |&simd| simd <= widest)
    }

    /// The build that runs: the widest this CPU has ([`Simd::cpu`]), capped by
    /// [`SIMD_ENV_VAR`] when that names a build (the command line rejects any other value:
    /// [`Simd::cap_from_env`]). Read once per process.
    pub fn detect() -> Self {
        static CHOSEN: OnceLock<Simd> = OnceLock::new();
        *CHOSEN.get_or_init(|| {
            let cpu = Self::cpu();
            Self::cap_from_env()
                .ok()
                .flatten()
                .map_or(cpu, |cap| cpu.min(cap))
        })
    }

    /// The widest build this CPU runs.
    pub fn cpu() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            let avx2 = has!("avx2") && has!("fma");
            if avx2 && has!("avx512f") && has!("avx512bw") && has!("avx512dq") && has!("avx512vl") {
                return Self::Avx512;
            }
            if avx2 {
                return Self::Avx2;
            }
        }
        Self::Baseline
    }

    /// The build's name, as [`SIMD_ENV_VAR`] takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Baseline => "baseline",
            Self::Avx2 => "avx2",
            Self::Avx512 => "avx512",
        }
    }

    /// The cap [`SIMD_ENV_VAR`] sets (`None` when unset or empty).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when it is set to anything but a build's name.
    pub fn cap_from_env() -> Result<Option<Self>> {
        let Some(value) = std::env::var_os(SIMD_ENV_VAR) else {
            return Ok(None);
        };
        let value = value.to_string_lossy();
        if value.is_empty() {
            return Ok(None);
        }
        Self::ALL
            .into_iter()
            .find(|simd| simd.name().eq_ignore_ascii_case(&value))
            .map(Some)
            .ok_or_else(|| Error::InvalidParameter {
                name: SIMD_ENV_VAR,
                value: value.into_owned(),
                expected: "baseline, avx2 or avx512 (or unset: the widest build the CPU runs)".into(),
            })
    }
}

/// `fn $name(simd, args…)`: runs `$generic(args…)` (an `#[inline(always)]` body) from a
/// baseline, an AVX2 + FMA or an AVX-512 function. Each is a separate non-inlined function
/// whose slice arguments the compiler knows do not alias. Const generic parameters, if given
/// (`$generic<const N: usize, …>`), become the kernel's own. A trailing `widest = Avx2` keeps a
/// kernel off its AVX-512 build where that build measured slower (the gathers: the compiler
/// turns them into AVX-512 gather instructions, slower there than the AVX2 build).
macro_rules! simd_kernel {
    (
        $name:ident,
        $avx2:ident,
        $generic:ident $(<$(const $g:ident: $gt:ty),+>)?,
        ($($arg:ident: $ty:ty),*) $(-> $ret:ty)?
        $(, widest = $widest:ident)?
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
                #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                unsafe fn avx512 $(<$(const $g: $gt),+>)? ($($arg: $ty),*) $(-> $ret)? {
                    $generic $(::<$($g),+>)? ($($arg),*)
                }
                #[allow(unused_variables)]
                let widest = $crate::simd::Simd::Avx512;
                $(let widest = $crate::simd::Simd::$widest;)?
                match simd.min(widest) {
                    // SAFETY: `Simd::Avx512` is only chosen when the CPU has these features
                    // (`Simd::detect`, `Simd::available`, or a request capped by `Simd::cpu`).
                    $crate::simd::Simd::Avx512 => return unsafe { avx512 $(::<$($g),+>)? ($($arg),*) },
                    // SAFETY: `Simd::Avx2` is only chosen when the CPU has AVX2 and FMA.
                    $crate::simd::Simd::Avx2 => return unsafe { $avx2 $(::<$($g),+>)? ($($arg),*) },
                    $crate::simd::Simd::Baseline => {}
                }
            }
            let _ = simd;
            $generic $(::<$($g),+>)? ($($arg),*)
        }
    };
}
pub(crate) use simd_kernel;
