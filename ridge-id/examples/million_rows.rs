//! Writes the speed benchmark's log (`scripts/bench-speed`): `N` rows (default 10⁶) of
//! `t,u,y` (s, input, output) from a known (2, 2, 0) ARX plant driven by a PRBS, with white
//! equation noise, numbers written with 4 decimals (about 23 MB for 10⁶ rows).
//!
//! ```text
//! cargo run --release -p ridge-id --example million_rows -- OUT.csv [N]
//! ```

use std::fs::File;
use std::io::{BufWriter, Write};

use pump_sim::arx::simulate_arx;
use ridge_core::excitation::Lfsr;

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
    // A PRBS input (ridge-core's 16-bit LFSR, each bit held 4 samples) between -1 and 1.
    let mut lfsr = Lfsr::new(16, 0xACE1).expect("a 16-bit LFSR");
    let mut level = 0.0;
    let u: Vec<f64> = (0..n)
        .map(|t| {
            if t % 4 == 0 {
                level = if lfsr.next_bit() { 1.0 } else { -1.0 };
            }
            level
        })
        .collect();
    let y = simulate_arx(&THETA, &PHI, 0, &u, 0.05, 7);
    let mut w = BufWriter::new(File::create(&out)?);
    writeln!(w, "t,u,y")?;
    for (i, (u, y)) in u.iter().zip(&y).enumerate() {
        writeln!(w, "{:.2},{u:.4},{y:.4}", i as f64 * 0.01)?;
    }
    w.flush()
}
