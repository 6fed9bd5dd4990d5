//! Properties of the rig simulator (`pump-sim`): determinism, dead zone, static
//! nonlinearity, transport delay, sensor noise, fault injection and CSV output.

use pump_sim::sfm3300::{raw_to_flow, Sfm3300Params};
use pump_sim::{record, record_with, Pump, PumpParams, Rig};
use ridge_pump_firmware::excitation::Record;

fn presets() -> [(&'static str, PumpParams); 3] {
    [
        ("default", PumpParams::default()),
        ("small", PumpParams::small()),
        ("sluggish", PumpParams::sluggish()),
    ]
}

/// True steady-state flow after holding `duty` for 10 s from rest.
fn settle(params: &PumpParams, duty: f64) -> f64 {
    let mut pump = Pump::new(params.clone());
    let mut q = 0.0;
    for _ in 0..1000 {
        q = pump.step(duty);
    }
    q
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    (m, s)
}

#[test]
fn same_seed_same_log_different_seed_different_noise() {
    let p = PumpParams::default();
    for r in Record::ALL {
        let a = record(r, &p, 11);
        let b = record(r, &p, 11);
        let c = record(r, &p, 12);
        assert_eq!(a, b, "{}", r.name());
        assert_eq!(a.raw_u, c.raw_u);
        assert_ne!(a.raw_y, c.raw_y, "{}", r.name());
        let differing = a.raw_y.iter().zip(&c.raw_y).filter(|(x, y)| x != y).count();
        assert!(differing > a.len() / 2, "{}: {differing}", r.name());
    }
}

#[test]
fn logs_follow_the_excitation() {
    let p = PumpParams::default();
    for r in Record::ALL {
        let log = record(r, &p, 1);
        assert_eq!(log.len(), r.len_samples() as usize);
        assert_eq!(log.y.len(), log.len());
        assert_eq!(log.raw_y.len(), log.len());
        let duties: Vec<u16> = r.generator().collect();
        assert_eq!(log.raw_u, duties);
        for (&u, &ru) in log.u.iter().zip(&log.raw_u) {
            assert_eq!(u, f64::from(ru) / 10_000.0);
            assert!((0.2..=0.9).contains(&u));
        }
        for (&y, &ry) in log.y.iter().zip(&log.raw_y) {
            assert_eq!(y, raw_to_flow(ry));
        }
        // The pump actually blows: flows up to >100 slm on every record.
        let ymax = log.y.iter().cloned().fold(f64::MIN, f64::max);
        assert!(ymax > 100.0, "{} max {ymax}", r.name());
    }
}

#[test]
fn dead_zone_gives_zero_flow() {
    for (name, p) in presets() {
        for duty in [0.0, 0.05, 0.10, p.start_duty - 0.005] {
            assert_eq!(settle(&p, duty), 0.0, "{name} at {duty}");
            assert_eq!(p.steady_state_flow(duty), 0.0);
        }
        // Measured: only the sensor's zero offset and floor noise remain.
        let mut rig = Rig::new(p.clone(), Sfm3300Params::default(), 3);
        let log = rig.run(std::iter::repeat_n(1_000u16, 500));
        let (m, s) = mean_std(&log.y);
        assert!((m - 0.1).abs() < 0.01, "{name}: mean {m}");
        assert!(s < 0.05, "{name}: std {s}");
    }
}

#[test]
fn steady_state_flow_is_monotone_and_nonlinear() {
    for (name, p) in presets() {
        let duties: Vec<f64> = (4..=20).map(|k| f64::from(k) * 0.05).collect(); // 20..100 %
        let flows: Vec<f64> = duties.iter().map(|&d| settle(&p, d)).collect();
        for (&d, &q) in duties.iter().zip(&flows) {
            assert!(
                (q - p.steady_state_flow(d)).abs() < 1e-6 * p.max_flow_slm,
                "{name} at {d}: {q}"
            );
        }
        for w in flows.windows(2) {
            assert!(w[1] > w[0], "{name}: not increasing {w:?}");
        }
        assert!(flows[0] > 0.0);
        assert!((flows[flows.len() - 1] - p.max_flow_slm).abs() < 1e-6 * p.max_flow_slm);
        // An affine plant would put q(80 %) on the line through q(40 %) and q(60 %):
        // q80 = 2 q60 − q40 (i.e. 2× the 40→60 rise plus the intercept). It is well above.
        let (q40, q60, q80) = (settle(&p, 0.4), settle(&p, 0.6), settle(&p, 0.8));
        let affine = 2.0 * q60 - q40;
        assert!(
            (q80 - affine) / q80 > 0.02,
            "{name}: q40 {q40} q60 {q60} q80 {q80}"
        );
        // Nor proportional to duty above the dead zone.
        let d0 = p.stop_duty;
        let prop = q40 * (0.8 - d0) / (0.4 - d0);
        assert!((q80 - prop).abs() / q80 > 0.02, "{name}");
    }
}

#[test]
fn transport_delay_is_exactly_k_samples() {
    for (name, p) in presets() {
        for k in [0usize, 1, p.delay_samples, 6] {
            let params = PumpParams {
                delay_samples: k,
                ..p.clone()
            };
            let mut rig = Rig::new(params, Sfm3300Params::ideal(), 0);
            let t0 = 800;
            let duties: Vec<u16> = (0..t0 + 50)
                .map(|t| if t < t0 { 4_000 } else { 6_000 })
                .collect();
            let log = rig.run(duties);
            // Settled before the step: flat.
            let before = log.raw_y[t0 - 1];
            assert_eq!(log.raw_y[t0 - 10], before);
            // u_t changes at t0; y stays put until t0 + k, then moves.
            for t in t0..t0 + k {
                assert_eq!(log.raw_y[t], before, "{name} k={k} t={t}");
            }
            assert!(log.raw_y[t0 + k] > before, "{name} k={k}");
            assert_eq!(log.raw_u[t0], 6_000);
            assert_eq!(log.raw_u[t0 - 1], 4_000);
        }
    }
}

#[test]
fn speed_lag_has_the_configured_time_constant() {
    // Start the rotor at 50 %, step to 80 %: after τ the speed has covered 1 − 1/e of the way.
    let p = PumpParams {
        delay_samples: 0,
        ..PumpParams::default()
    };
    let mut pump = Pump::new(p.clone());
    for _ in 0..1000 {
        pump.step(0.5);
    }
    let s0 = pump.speed();
    let s1 = p.steady_state_speed(0.8);
    let n_tau = (p.tau_up_s / p.ts_s).round() as usize; // 15 samples
    for _ in 0..n_tau {
        pump.step(0.8);
    }
    let frac = (pump.speed() - s0) / (s1 - s0);
    assert!((frac - (1.0 - (-1.0f64).exp())).abs() < 1e-9, "{frac}");
}

#[test]
fn sensor_noise_is_about_3_percent_of_reading() {
    for duty in [3_000u16, 6_000, 9_000] {
        let p = PumpParams::default();
        let truth = p.steady_state_flow(f64::from(duty) / 10_000.0);
        let mut rig = Rig::new(p, Sfm3300Params::default(), 99);
        let log = rig.run(std::iter::repeat_n(duty, 6_000));
        let (m, s) = mean_std(&log.y[1_000..]);
        let rel = s / truth;
        assert!((rel - 0.03).abs() < 0.003, "duty {duty}: rel std {rel}");
        assert!(
            (m - truth - 0.1).abs() < 0.05 + 0.002 * truth,
            "duty {duty}: mean {m}"
        );
    }
}

#[test]
fn stalled_rotor_gives_zero_flow_and_recovers() {
    let mut rig = Rig::new(PumpParams::default(), Sfm3300Params::default(), 5);
    let spin = rig.run(std::iter::repeat_n(6_000u16, 300));
    assert!(spin.y[299] > 50.0);
    rig.pump.set_stalled(true);
    assert!(rig.pump.is_stalled());
    let stalled = rig.run(std::iter::repeat_n(6_000u16, 300));
    assert!(
        stalled.y.iter().all(|&y| y.abs() < 0.3),
        "{:?}",
        &stalled.y[..5]
    );
    rig.pump.set_stalled(false);
    let again = rig.run(std::iter::repeat_n(6_000u16, 300));
    assert!(again.y[299] > 50.0);
}

#[test]
fn csv_has_header_time_and_round_trips() {
    let log = record_with(
        Record::BRamp,
        &PumpParams::small(),
        &Sfm3300Params::default(),
        8,
    );
    let path = std::env::temp_dir().join(format!("ridge-sim-{}.csv", std::process::id()));
    log.write_csv(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t,u,y"));
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), log.len());
    for (i, row) in rows.iter().enumerate() {
        let f: Vec<f64> = row.split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(f.len(), 3);
        assert!((f[0] - i as f64 * 0.01).abs() < 1e-9);
        assert_eq!(f[1], log.u[i]);
        assert_eq!(f[2], log.y[i]);
    }
    assert!(rows[1].starts_with("0.01,"));
}

/// Prints the plant facts quoted in reports (`cargo test -p pump-sim --test sim -- --nocapture facts`).
#[test]
fn facts() {
    for (name, p) in presets() {
        let q: Vec<String> = [0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
            .iter()
            .map(|&d| format!("{:.0}%:{:.1}", d * 100.0, settle(&p, d)))
            .collect();
        println!("{name}: steady-state slm {}", q.join(" "));
    }
    let p = PumpParams::default();
    for duty in [3_000u16, 6_000, 9_000] {
        let truth = p.steady_state_flow(f64::from(duty) / 10_000.0);
        let mut rig = Rig::new(p.clone(), Sfm3300Params::default(), 99);
        let log = rig.run(std::iter::repeat_n(duty, 6_000));
        let (m, s) = mean_std(&log.y[1_000..]);
        println!(
            "default at {}%: true {truth:.2} slm, measured mean {m:.3}, std {s:.3} ({:.2} % of reading)",
            duty / 100,
            100.0 * s / truth
        );
    }
    for r in Record::ALL {
        let log = record(r, &p, 1);
        let ymax = log.y.iter().cloned().fold(f64::MIN, f64::max);
        let ymin = log.y.iter().cloned().fold(f64::MAX, f64::min);
        println!(
            "default {}: N={} y in [{ymin:.2}, {ymax:.2}] slm",
            r.name(),
            log.len()
        );
    }
}
