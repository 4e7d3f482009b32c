//! A branch-free `exp` for non-positive arguments that LLVM can vectorise (libm's `exp` is an
//! opaque call that blocks SIMD). Used on log-responsibilities shifted by their maximum.

const LOG2E: f64 = std::f64::consts::LOG2_E;
const LN2_HI: f64 = 6.931_471_803_691_238e-1;
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
/// 1.5 * 2^52: adding it rounds to the nearest integer and leaves that integer in the low bits.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

/// exp(x) for x <= 0 with relative error below 1e-13; arguments under -700 return ~1e-304.
#[inline(always)]
pub fn exp_nonpos(x: f64) -> f64 {
    let x = x.max(-700.0);
    let t = x * LOG2E + ROUND_MAGIC;
    let n = t - ROUND_MAGIC;
    let r = (x - n * LN2_HI) - n * LN2_LO; // |r| <= ln2 / 2
                                           // Taylor series to degree 11: the truncation error is below 3e-15 on |r| <= 0.347.
    let mut p = 1.0 / 39_916_800.0;
    p = p * r + 1.0 / 3_628_800.0;
    p = p * r + 1.0 / 362_880.0;
    p = p * r + 1.0 / 40_320.0;
    p = p * r + 1.0 / 5_040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    // Scale by 2^n: n sits in the low bits of t (two's complement), shift it into the exponent.
    f64::from_bits(p.to_bits().wrapping_add(t.to_bits() << 52))
}

#[cfg(test)]
mod tests {
    use super::exp_nonpos;

    #[test]
    fn matches_libm() {
        let mut x = 0.0;
        while x > -745.0 {
            let (got, want) = (exp_nonpos(x), x.max(-700.0).exp());
            assert!(
                ((got - want) / want).abs() < 1e-13,
                "x={x} got={got} want={want}"
            );
            x -= 0.0137;
        }
    }
}
