//! Measured initial conditions (`--initial measured`, the default): a known ARX plant logged
//! from a non-zero operating point is recovered exactly with the default options, and the
//! statistics equal an explicit regression over rows `M+1..N`.

mod common;

use std::fs;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use pump_sim::arx::simulate_arx;
use ridge_core_host::Structure;
use ridge_id::{run, Initial, Options};

/// The known plant: (p, q, d) = (2, 2, 2), static gain (1 + 0.5) / (1 − 1.5 + 0.7) = 7.5.
const THETA: [f64; 2] = [1.5, -0.7];
const PHI: [f64; 2] = [1.0, 0.5];
const DELAY: usize = 2;

/// Deterministic steps in [-1, 1], held 3..=20 samples.
fn steps(n: usize, seed: u64) -> Vec<f64> {
    common::steps(n, seed, -1.0, 2.0, 3, 18.0)
}

/// A log of the plant in equilibrium at `u0` (y0 = 7.5 u0) before the record starts, then
/// driven by steps around `u0`: in absolute values the ARX equation holds exactly, without an
/// intercept, but the record starts far from zero.
fn operating_point_log(name: &str, n: usize, u0: f64, noise: f64, seed: u64) -> PathBuf {
    let du = steps(n, seed);
    let dy = simulate_arx(&THETA, &PHI, DELAY, &du, noise, seed);
    let y0 = 7.5 * u0;
    let path = std::env::temp_dir().join(format!("ridge_id_initial_{name}.csv"));
    let mut w = BufWriter::new(fs::File::create(&path).unwrap());
    writeln!(w, "t,u,y").unwrap();
    for (i, (du, dy)) in du.iter().zip(&dy).enumerate() {
        writeln!(w, "{i},{},{}", u0 + du, y0 + dy).unwrap();
    }
    w.flush().unwrap();
    path
}

#[test]
fn known_plant_from_an_operating_point_is_recovered_with_default_options() {
    for (u0, seed) in [(2.0, 11), (-3.0, 12), (5.0, 13)] {
        let est = operating_point_log(&format!("est{seed}"), 4000, u0, 0.05, seed);
        let opts = Options::new(&est);
        assert_eq!(opts.hyper.initial, Initial::Measured);
        let r = run(&opts).unwrap();
        assert_eq!(
            r.model.structure(),
            Structure::new(2, 2, 2).unwrap(),
            "u0 {u0}: {}",
            r.to_text()
        );
        for (got, want) in r
            .model
            .theta()
            .iter()
            .chain(r.model.phi())
            .zip(THETA.iter().chain(&PHI))
        {
            assert!((got - want).abs() < 0.02, "u0 {u0}: {got} vs {want}");
        }
        assert_eq!(r.initial_samples, 11);
        assert!(r.to_text().contains("measured: the first M = 11 samples"));
        assert_eq!(r.to_json()["hyper"]["initial"], "measured");
    }
}
