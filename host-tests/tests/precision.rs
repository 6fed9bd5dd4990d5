//! f32 against f64 on realistic data: the simulated pump through exact integer statistics
//! (the device path), and the float statistics path (the host path).
use pump_sim::{record, PumpParams};
use ridge_core::{FloatGram, IntGram, Normal, Scale, Search, Structure};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::SCALE;

fn int_gram(log: &pump_sim::Log) -> IntGram {
    let mut g = IntGram::new();
    for (&u, &y) in log.raw_u.iter().zip(&log.raw_y) {
        g.push(i32::from(u), i32::from(y) - 32768).unwrap();
    }
    g
}

fn max_rel(a: &[f32], b: &[f64]) -> f64 {
    let scale = b.iter().map(|v| v.abs()).fold(0.0, f64::max);
    a.iter()
        .zip(b)
        .map(|(x, y)| (f64::from(*x) - y).abs() / scale)
        .fold(0.0, f64::max)
}

/// Structure, θ, φ of the default search, as f64 for comparison.
fn pick<T: ridge_core::Real>(n: &Normal<T>) -> (Structure, Vec<f64>, Vec<f64>, f64) {
    let sel = Search::<T>::default().run(n, None).unwrap();
    let m = sel.fit.model();
    (
        sel.structure(),
        m.theta().iter().map(|v| v.to_f64()).collect(),
        m.phi().iter().map(|v| v.to_f64()).collect(),
        sel.fit.rss.to_f64(),
    )
}

#[test]
fn f32_and_f64_agree_on_the_simulated_pump() {
    let mut report = Vec::new();
    for (k, rec) in [Record::AMultistep, Record::BMultistep, Record::Prbs]
        .into_iter()
        .enumerate()
    {
        for params in [
            PumpParams::default(),
            PumpParams::small(),
            PumpParams::sluggish(),
        ] {
            let log = record(rec, &params, 40 + k as u64);
            let g = int_gram(&log);
            let n32 = g.normal::<f32>(SCALE).unwrap();
            let n64 = g.normal::<f64>(SCALE).unwrap();
            let (s32, t32, p32, rss32) = pick(&n32);
            let (s64, t64, p64, rss64) = pick(&n64);
            assert_eq!(s32, s64, "{rec:?}: f32 and f64 pick different structures");
            let t32: Vec<f32> = t32.iter().map(|v| *v as f32).collect();
            let p32: Vec<f32> = p32.iter().map(|v| *v as f32).collect();
            let (dt, dp) = (max_rel(&t32, &t64), max_rel(&p32, &p64));
            let drss = (rss32 - rss64).abs() / rss64;
            report.push((rec, s64, dt, dp, drss));
            // Measured: ≤ 1.4e-5 relative on θ and φ, ≤ 1e-6 on the RSS (see README).
            assert!(
                dt < 1e-4 && dp < 1e-4,
                "{rec:?} {s64:?}: θ {dt:e}, φ {dp:e}"
            );
            assert!(drss < 1e-5, "{rec:?}: RSS {drss:e}");
        }
    }
    for r in &report {
        println!(
            "{:?} {:?}: max rel diff θ {:.1e} φ {:.1e} RSS {:.1e}",
            r.0, r.1, r.2, r.3, r.4
        );
    }
}

#[test]
fn float_statistics_agree_with_exact_statistics() {
    // The host path (f64 sums of physical values) against the device path (exact integer
    // sums, scaled at solve time): same pick, same coefficients.
    let log = record(Record::AMultistep, &PumpParams::default(), 7);
    let exact = int_gram(&log).normal::<f64>(SCALE).unwrap();
    let mut f = FloatGram::new();
    for (&u, &y) in log.u.iter().zip(&log.y) {
        f.push(u, y).unwrap();
    }
    let float = f.normal::<f64>(Scale::UNIT).unwrap();
    let (se, te, pe, _) = pick(&exact);
    let (sf, tf, pf, _) = pick(&float);
    assert_eq!(se, sf);
    let tf: Vec<f32> = tf.iter().map(|v| *v as f32).collect();
    let pf: Vec<f32> = pf.iter().map(|v| *v as f32).collect();
    assert!(max_rel(&tf, &te) < 1e-5 && max_rel(&pf, &pe) < 1e-5);
}

#[test]
fn f32_float_accumulation_would_not_be_exact() {
    // Why the device accumulates integers: summing the same products in f32
    // loses digits that the i64 sums keep. Measured here on Σy² of a 30 000-sample record.
    let mut y_counts = Vec::new();
    for seed in 0..10 {
        let log = record(Record::AMultistep, &PumpParams::default(), 100 + seed);
        y_counts.extend(log.raw_y.iter().map(|&r| i64::from(r) - 32768));
    }
    let exact: i64 = y_counts.iter().map(|v| v * v).sum();
    let f32sum: f32 = y_counts.iter().map(|&v| (v as f32) * (v as f32)).sum();
    let rel = (f64::from(f32sum) - exact as f64).abs() / exact as f64;
    println!(
        "f32 accumulation of Σy² over {} samples: relative error {rel:.1e}",
        y_counts.len()
    );
    assert!(rel > 1e-6, "f32 sums are visibly inexact");
}
