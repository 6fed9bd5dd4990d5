//! Number formatting for ridge-id's reports and messages: a leaf module (it knows `f64`
//! only), used by the computation's messages and by the text printer alike.

/// A figure of a report: `1.234568`, `-0.001250` (six decimals), or `1.23457e-7`,
/// `2.50000e6` (scientific, five decimals) when the magnitude is outside `1e-3..1e6`;
/// `NaN`, `inf` as Rust writes them.
pub fn num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{v:.5e}")
    } else {
        format!("{v:.6}")
    }
}

/// A setting as it would be typed: `1000`, `0.01`, `1e-6`, `1e300` (the shortest decimal that
/// reads back, scientific outside `1e-3..1e7`).
pub fn typed(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e7).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A coefficient list: `[1.000000, -0.500000]`, each entry as [`num`].
pub fn list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| num(*x)).collect();
    format!("[{}]", items.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_settings_and_lists() {
        assert_eq!(num(1.2345678), "1.234568");
        assert_eq!(num(-0.00125), "-0.001250");
        assert_eq!(num(-0.000125), "-1.25000e-4");
        assert_eq!(num(1.2345678e-7), "1.23457e-7");
        assert_eq!(num(2.5e6), "2.50000e6");
        assert_eq!(num(0.0), "0.000000");
        assert_eq!(num(f64::NAN), "NaN");
        assert_eq!(typed(1000.0), "1000");
        assert_eq!(typed(0.01), "0.01");
        assert_eq!(typed(1e-6), "1e-6");
        assert_eq!(typed(1e300), "1e300");
        assert_eq!(list(&[1.0, -0.5]), "[1.000000, -0.500000]");
        assert_eq!(list(&[]), "[]");
    }
}
