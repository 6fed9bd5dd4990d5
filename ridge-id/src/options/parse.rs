//! Parsers of the command line's order ranges (`--p 1..=6`) and fixed structures
//! (`--structure 2,2,3`), with messages saying the accepted range.

use ridge_core_host::{OrderRange, Structure, D_MAX, P_MAX, Q_MAX};

/// Parses an inclusive order range: `1..=6` or a single number `3`, checked against
/// `lo..=hi`.
pub fn parse_range(s: &str, lo: u8, hi: u8) -> Result<OrderRange, String> {
    let num = |t: &str| -> Result<u8, String> {
        let t = t.trim();
        t.parse::<u8>()
            .ok()
            .filter(|v| (lo..=hi).contains(v))
            .ok_or_else(|| format!("{t:?} is not a whole number in {lo}..={hi}"))
    };
    let r = if let Some((a, b)) = s.split_once("..=") {
        OrderRange::new(num(a)?, num(b)?)
    } else if s.contains("..") {
        return Err(format!(
            "{s:?}: write an inclusive range as a..=b (e.g. {lo}..={hi}) or a single number"
        ));
    } else {
        let v = num(s)?;
        OrderRange::new(v, v)
    };
    if r.min > r.max {
        return Err(format!("{s:?} is an empty range"));
    }
    Ok(r)
}

/// Parses a fixed structure `P,Q,D`, e.g. `2,2,3`.
pub fn parse_structure(s: &str) -> Result<Structure, String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [p, q, d] = parts.as_slice() else {
        return Err(format!("{s:?}: expected P,Q,D (three numbers, e.g. 2,2,3)"));
    };
    let p = parse_range(p, 1, P_MAX as u8)?.min;
    let q = parse_range(q, 1, Q_MAX as u8)?.min;
    let d = parse_range(d, 0, D_MAX as u8)?.min;
    Structure::new(p, q, d).map_err(|e| format!("{s:?}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges() {
        assert_eq!(parse_range("1..=6", 1, 6), Ok(OrderRange::new(1, 6)));
        assert_eq!(parse_range("3", 1, 6), Ok(OrderRange::new(3, 3)));
        assert_eq!(parse_range(" 0 ..= 2", 0, 6), Ok(OrderRange::new(0, 2)));
        assert!(parse_range("1..6", 1, 6).unwrap_err().contains("a..=b"));
        assert!(parse_range("0", 1, 6).is_err());
        assert!(parse_range("7", 1, 6).is_err());
        assert!(parse_range("4..=2", 1, 6).unwrap_err().contains("empty"));
        assert!(parse_range("x", 1, 6).is_err());
    }

    #[test]
    fn structures() {
        assert_eq!(
            parse_structure("2,2,3"),
            Structure::new(2, 2, 3).map_err(|e| e.to_string())
        );
        assert!(parse_structure("2,2").is_err());
        assert!(parse_structure("0,1,0").is_err());
    }
}
