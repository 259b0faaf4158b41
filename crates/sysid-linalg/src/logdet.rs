/// Accumulates `sum_i ln(d_i)` of positive numbers without calling `ln` per term:
/// mantissas are multiplied and binary exponents added, which is exact apart from the
/// final logarithm and about ten times cheaper than one `ln` per term.
///
/// # Example
/// ```
/// let mut acc = sysid_linalg::LogProduct::new();
/// for d in [1e-200, 3.0, 1e250, 0.5] { acc.push(d); }
/// let exact: f64 = [1e-200_f64, 3.0, 1e250, 0.5].iter().map(|d| d.ln()).sum();
/// assert!((acc.ln() - exact).abs() < 1e-12 * exact.abs());
/// ```
#[derive(Debug, Clone, Copy)]
pub struct LogProduct {
    mantissa: f64,
    exponent: i64,
    extra: f64,
}

impl Default for LogProduct {
    fn default() -> Self {
        Self::new()
    }
}

const EXP_MASK: u64 = 0x7ff << 52;

impl LogProduct {
    /// The empty product (log 0.0).
    pub fn new() -> Self {
        LogProduct {
            mantissa: 1.0,
            exponent: 0,
            extra: 0.0,
        }
    }

    /// Multiplies by `d > 0` (subnormal or non-finite `d` fall back to `ln`).
    #[inline]
    pub fn push(&mut self, d: f64) {
        if !d.is_normal() {
            self.extra += d.ln();
            return;
        }
        let m = self.mantissa * d;
        let bits = m.to_bits();
        self.exponent += ((bits & EXP_MASK) >> 52) as i64 - 1023;
        self.mantissa = f64::from_bits((bits & !EXP_MASK) | (1023 << 52));
    }

    /// `sum_i ln(d_i)`.
    pub fn ln(&self) -> f64 {
        self.exponent as f64 * std::f64::consts::LN_2 + self.mantissa.ln() + self.extra
    }
}
