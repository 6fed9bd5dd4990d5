//! Writes the speed benchmark's log (`scripts/bench-speed`): `N` rows (default 10⁶) of
//! `t,u,y` (s, input, output) from a known (2, 2, 0) ARX plant driven by random steps, with
//! white equation noise, numbers written with 4 decimals (27 MB for 10⁶ rows).
//!
//! ```text
//! cargo run --release -p ridge-id --example million_rows -- OUT.csv [N]
//! ```

use std::fs::File;
use std::io::{BufWriter, Write};

use pump_sim::arx::simulate_arx;

/// The plant: `y_t = 1.5 y_{t-1} − 0.7 y_{t-2} + u_t + 0.5 u_{t-1} + e_t`.
const THETA: [f64; 2] = [1.5, -0.7];
const PHI: [f64; 2] = [1.0, 0.5];

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = args.next().unwrap_or_else(|| {
        eprintln!("usage: million_rows OUT.csv [ROWS]");
        std::process::exit(2)
    });
    let n: usize = args.next().map_or(1_000_000, |a| {
        a.parse().unwrap_or_else(|_| {
            eprintln!("ROWS must be a whole number, not {a:?}");
            std::process::exit(2)
        })
    });
    // Random steps: levels in [-1, 1] held 3..=20 samples (a 64-bit LCG, deterministic).
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 33) as f64 / (1u64 << 31) as f64
    };
    let mut u = Vec::with_capacity(n);
    while u.len() < n {
        let level = 2.0 * next() - 1.0;
        let hold = 3 + (next() * 18.0) as usize;
        u.extend(std::iter::repeat_n(level, hold.min(n - u.len())));
    }
    let y = simulate_arx(&THETA, &PHI, 0, &u, 0.05, 7);
    let mut w = BufWriter::new(File::create(&out)?);
    writeln!(w, "t,u,y")?;
    for (i, (u, y)) in u.iter().zip(&y).enumerate() {
        writeln!(w, "{:.2},{u:.4},{y:.4}", i as f64 * 0.01)?;
    }
    w.flush()
}
