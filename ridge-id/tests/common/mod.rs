//! Helpers shared by ridge-id's integration tests (`mod common;` in each).
#![allow(dead_code)] // each test crate uses its own part

/// One step of the 64-bit linear congruential generator of these tests (Knuth's MMIX
/// constants).
pub fn lcg(s: u64) -> u64 {
    s.wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407)
}

/// `n` samples of a deterministic random-step input: levels `lo + span · x`, each held
/// `min_hold + ⌊x′ · hold_span⌋` samples, `x`, `x′` uniform in [0, 1) from [`lcg`] started at
/// `state` (two draws per level).
pub fn steps(
    n: usize,
    state: u64,
    lo: f64,
    span: f64,
    min_hold: usize,
    hold_span: f64,
) -> Vec<f64> {
    let mut s = state;
    let mut next = || {
        s = lcg(s);
        (s >> 33) as f64 / (1u64 << 31) as f64
    };
    let mut u = Vec::with_capacity(n);
    while u.len() < n {
        let level = lo + span * next();
        let hold = min_hold + (next() * hold_span) as usize;
        u.extend(std::iter::repeat_n(level, hold.min(n - u.len())));
    }
    u
}
