//! Tukey bi-square robust loss (paper Eq. 13) and its IRLS weight.
//!
//! ρ_k(r) = k²/6 · (1 − (1 − (r/k)²)³) for |r| ≤ k, and k²/6 beyond (an outlier costs a constant
//! and exerts no pull). The IRLS weight is ψ(r)/r = (1 − (r/k)²)² inside, 0 outside; it is what
//! multiplies JᵀJ and Jᵀr in the normal equations, so the weighted Gauss–Newton step is the
//! Newton-like step of Σ ρ(r).

/// The bi-square loss ρ_k(r) and IRLS weight w_k(r) = ψ(r)/r, as `(rho, weight)`.
#[inline(always)]
pub fn bisquare(residual: f32, k: f32) -> (f32, f32) {
    let s = residual / k;
    let s2 = s * s;
    if s2 < 1.0 {
        let one_minus = 1.0 - s2;
        let w = one_minus * one_minus;
        (k * k * (1.0 / 6.0) * (1.0 - w * one_minus), w)
    } else {
        (bisquare_saturated(k), 0.0)
    }
}

/// The loss of an outlier (|r| ≥ k): k²/6. Also charged for a reference point that cannot be
/// evaluated at a candidate pose (projects outside the image or onto missing depth), so that
/// moving points out of view is never a way to lower the cost.
#[inline(always)]
pub fn bisquare_saturated(k: f32) -> f32 {
    k * k * (1.0 / 6.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_is_psi_over_r() {
        // ψ = dρ/dr by central differences, compared with w·r.
        let k = 0.2f32;
        for &r in &[-0.19f32, -0.1, -0.01, 0.003, 0.05, 0.15] {
            let h = 1e-3f32;
            let psi = (bisquare(r + h, k).0 - bisquare(r - h, k).0) / (2.0 * h);
            let (_, w) = bisquare(r, k);
            assert!((psi - w * r).abs() < 1e-4, "r {r}: psi {psi} vs {}", w * r);
        }
    }

    #[test]
    fn saturates_beyond_k_and_is_zero_at_zero() {
        let k = 0.5;
        assert_eq!(bisquare(0.0, k), (0.0, 1.0));
        assert_eq!(bisquare(0.6, k), (bisquare_saturated(k), 0.0));
        assert_eq!(bisquare(-2.0, k), (bisquare_saturated(k), 0.0));
        // Continuous at the threshold.
        assert!((bisquare(0.4999, k).0 - bisquare_saturated(k)).abs() < 1e-6);
    }
}
