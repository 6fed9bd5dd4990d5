//! `ridge-id identify … --control` end to end, against an independent truth: logs simulated
//! from known ARX plants (`pump_sim::arx::simulate_arx`), the binary run with `--json`, and
//! everything checked from the JSON alone with code of its own here: the closed-loop
//! polynomial `P = A R + q^{−d−1} B S` rebuilt from `r`, `s` and the model's `θ`, `φ`, `d`,
//! its roots (nalgebra's companion-matrix eigenvalues, computed here), the controller run on
//! the *true* plant (not the identified model), and the refusals (exit status 3, a reason).

mod common;

use std::fs;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use nalgebra::DMatrix;
use pump_sim::arx::simulate_arx;
use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_ridge-id");

/// Exit status of a refused controller.
const REFUSED: i32 = 3;

fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("ridge_id_control");
    fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn ridge_id(args: &[&str]) -> Output {
    Command::new(BIN)
        .arg("identify")
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap()
}

/// A known plant `y_t = Σθ y_{t−i} + Σφ u_{t−j−d} + c` (`c` added as the output offset
/// `c / (1 − Σθ)` of pump-sim's simulation).
#[derive(Clone, Copy)]
struct Plant {
    theta: &'static [f64],
    phi: &'static [f64],
    d: usize,
    /// Output offset at steady state (`c / A(1)`).
    y_offset: f64,
}

/// Blower-like: poles 0.95 (the lag) and 0.4, delay 2, gain 0.8 / 0.03 ≈ 26.7, offset 2.
const BLOWER: Plant = Plant {
    theta: &[1.35, -0.38],
    phi: &[0.5, 0.3],
    d: 2,
    y_offset: 2.0,
};

/// A deterministic random-step input: levels in [0.2, 0.8] held 3..=40 samples.
fn steps(n: usize, seed: u64) -> Vec<f64> {
    common::steps(n, seed, 0.2, 0.6, 3, 38.0)
}

fn log(name: &str, plant: Plant, n: usize, noise: f64, seed: u64) -> PathBuf {
    let u = steps(n, seed);
    let y = simulate_arx(plant.theta, plant.phi, plant.d, &u, noise, seed);
    let p = tmp(name);
    let mut w = BufWriter::new(fs::File::create(&p).unwrap());
    writeln!(w, "t,u,y").unwrap();
    for (i, (u, y)) in u.iter().zip(&y).enumerate() {
        writeln!(w, "{},{u},{}", i as f64 * 0.01, y + plant.y_offset).unwrap();
    }
    w.flush().unwrap();
    p
}

fn stdout_json(out: &Output) -> Value {
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    assert_eq!(text.lines().count(), 1, "one JSON line: {text}");
    serde_json::from_str(&text).unwrap()
}

fn ok_json(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "exit {:?}, stderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    stdout_json(out)
}

fn vec_of(v: &Value) -> Vec<f64> {
    serde_json::from_value(v.clone()).unwrap()
}

/// `a · b`, ascending powers.
fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// The roots of `a(q⁻¹)` (ascending powers), trailing coefficients below `zero` dropped
/// (roots at 0), as (re, im) sorted by (re, im).
fn roots(a: &[f64], zero: f64) -> Vec<(f64, f64)> {
    let mut n = a.len();
    while n > 1 && a[n - 1].abs() <= zero {
        n -= 1;
    }
    let deg = n - 1;
    let mut out: Vec<(f64, f64)> = vec![(0.0, 0.0); a.len() - n];
    if deg > 0 {
        let mut m = DMatrix::<f64>::zeros(deg, deg);
        for j in 0..deg {
            m[(0, j)] = -a[j + 1] / a[0];
        }
        for i in 1..deg {
            m[(i, i - 1)] = 1.0;
        }
        out.extend(m.complex_eigenvalues().iter().map(|z| (z.re, z.im)));
    }
    out.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)));
    out
}

/// The model of the JSON: (A, q^{−d−1} B).
fn model_polys(j: &Value) -> (Vec<f64>, Vec<f64>) {
    let theta = vec_of(&j["theta"]);
    let phi = vec_of(&j["phi"]);
    let d = j["structure"]["d"].as_u64().unwrap() as usize;
    let a: Vec<f64> = std::iter::once(1.0)
        .chain(theta.iter().map(|t| -t))
        .collect();
    let mut b1 = vec![0.0; d + 1];
    b1.extend(phi);
    (a, b1)
}

/// Runs `R u_{t+1} = T r_{t+1} − S y_t` (no limits) on `plant` from its steady state at
/// `u0`, the setpoint stepping by `dr` at sample 10; returns (r, y, u) over `n` samples.
fn closed_loop_on(
    plant: Plant,
    r_: &[f64],
    s_: &[f64],
    t_: &[f64],
    u0: f64,
    dr: f64,
    n: usize,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let a1: f64 = 1.0 - plant.theta.iter().sum::<f64>();
    let gain = plant.phi.iter().sum::<f64>() / a1;
    let c = plant.y_offset * a1;
    let y0 = gain * u0 + plant.y_offset;
    let pad = 20;
    let mut u = vec![u0; pad + n];
    let mut y = vec![y0; pad + n];
    let mut r: Vec<f64> = (0..pad + n)
        .map(|k| if k >= pad + 10 { y0 + dr } else { y0 })
        .collect();
    for t in pad - 1..pad + n - 1 {
        // u_{t+1} from r_{t+1}, y_t and the past inputs.
        let mut v = 0.0;
        for (k, tk) in t_.iter().enumerate() {
            v += tk * r[t + 1 - k];
        }
        for (k, sk) in s_.iter().enumerate() {
            v -= sk * y[t - k];
        }
        for (k, rk) in r_.iter().enumerate().skip(1) {
            v -= rk * u[t + 1 - k];
        }
        u[t + 1] = v / r_[0];
        // The true plant: y_{t+1}.
        let mut w = c;
        for (i, th) in plant.theta.iter().enumerate() {
            w += th * y[t - i];
        }
        for (j, ph) in plant.phi.iter().enumerate() {
            w += ph * u[t + 1 - plant.d - j];
        }
        y[t + 1] = w;
    }
    (r.split_off(pad), y.split_off(pad), u.split_off(pad))
}

/// First sample at which the response has covered `frac` of the step (after sample 10).
fn crossing(r: &[f64], y: &[f64], frac: f64) -> usize {
    let (y0, r1) = (y[0], r[r.len() - 1]);
    y.iter()
        .position(|&v| (v - y0) / (r1 - y0) >= frac)
        .expect("reaches the level")
}

fn designed(args: &[&str]) -> Value {
    let j = ok_json(&ridge_id(args));
    assert_eq!(j["control"]["method"], "pole-placement", "{j}");
    j
}

#[test]
fn closed_loop_from_the_json_is_the_reported_one_and_tracks_the_true_plant() {
    let est = log("blower.csv", BLOWER, 3000, 0.01, 11);
    let path = est.to_str().unwrap();
    // The searched structure and the true one (2,2,2): both must give a sound controller.
    for extra in [&[][..], &["--structure", "2,2,2"][..]] {
        let mut args = vec![
            "--input",
            path,
            "--offset",
            "intercept",
            "--control",
            "--json",
        ];
        args.extend(extra);
        let j = designed(&args);
        let c = &j["control"];
        let mut keys: Vec<&str> = c.as_object().unwrap().keys().map(String::as_str).collect();
        keys.sort();
        assert_eq!(
            keys,
            [
                "alpha",
                "ao",
                "beta",
                "gamma",
                "kept",
                "mean_delay_samples",
                "method",
                "modulus_margin",
                "poles",
                "r",
                "reference_s",
                "s",
                "t",
                "tau_s",
                "tries",
                "ts_s"
            ]
        );
        let (r, s, t) = (vec_of(&c["r"]), vec_of(&c["s"]), vec_of(&c["t"]));
        let (a, b1) = model_polys(&j);

        // (a) P = A R + q^{−d−1} B S, rebuilt here; its roots are the JSON's poles.
        let ar = mul(&a, &r);
        let bs = mul(&b1, &s);
        let mut p = vec![0.0; ar.len().max(bs.len())];
        for (k, v) in ar.iter().enumerate() {
            p[k] += v;
        }
        for (k, v) in bs.iter().enumerate() {
            p[k] += v;
        }
        let scale = ar.iter().chain(&bs).fold(0.0f64, |m, v| m.max(v.abs()));
        let mine = roots(&p, 1e-10 * scale);
        let mut theirs: Vec<(f64, f64)> = c["poles"]
            .as_array()
            .unwrap()
            .iter()
            .map(|z| (z[0].as_f64().unwrap(), z[1].as_f64().unwrap()))
            .collect();
        theirs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)));
        assert_eq!(mine.len(), p.len() - 1, "degree of P");
        assert_eq!(mine.len(), theirs.len(), "{mine:?} vs {theirs:?}");
        for (m, o) in mine.iter().zip(&theirs) {
            assert!(
                (m.0 - o.0).abs() < 1e-6 && (m.1 - o.1).abs() < 1e-6,
                "{mine:?} vs {theirs:?}"
            );
            assert!(m.0.hypot(m.1) < 1.0, "unstable closed loop: {mine:?}");
        }
        // Without --speed the firmware's reference model: 0.08 s, γ = e^{−Ts/0.08}.
        assert_eq!(c["reference_s"].as_f64(), Some(0.08), "{c}");
        let gamma = c["gamma"].as_f64().unwrap();
        assert!((gamma - (-0.01f64 / 0.08).exp()).abs() < 1e-7, "{gamma}");
        // The designed poles α (regulation), β (observer) and the reference model's γ (the
        // setpoint response's, multiplied into R and S) are among them.
        for key in ["alpha", "beta", "gamma"] {
            let want = c[key].as_f64().unwrap();
            assert!(
                mine.iter()
                    .any(|z| (z.0 - want).abs() < 1e-6 && z.1.abs() < 1e-6),
                "{key} {want} not a root: {mine:?}"
            );
        }
        let margin = c["modulus_margin"].as_f64().unwrap();
        assert!((0.5..=1.0).contains(&margin), "{margin}");

        // (b) Integral action and unit static gain.
        let sum = |v: &[f64]| v.iter().sum::<f64>();
        let size = |v: &[f64]| v.iter().map(|x| x.abs()).sum::<f64>();
        assert_eq!(r[0], 1.0);
        assert!(sum(&r).abs() < 1e-9 * size(&r), "R(1) = {}", sum(&r));
        assert!(
            (sum(&t) - sum(&s)).abs() < 1e-9 * size(&s),
            "T(1) {} vs S(1) {}",
            sum(&t),
            sum(&s)
        );

        // (c) On the true plant (with its offset, which the controller is not told about):
        // the setpoint is reached without steady error, and the loop settles.
        let (rr, y, u) = closed_loop_on(BLOWER, &r, &s, &t, 0.5, 1.5, 400);
        let last = y.len() - 1;
        assert!(
            (y[last] - rr[last]).abs() < 1e-6,
            "steady error {}",
            y[last] - rr[last]
        );
        assert!((u[last] - u[last - 1]).abs() < 1e-9);
        // Stable and without a large overshoot (the model is close to the plant).
        let peak = y.iter().fold(f64::MIN, |m, &v| m.max(v));
        assert!(peak < rr[last] + 0.2 * 1.5, "overshoot: peak {peak}");
    }
}

#[test]
fn a_slower_speed_gives_a_slower_step_response() {
    let est = log("speed.csv", BLOWER, 3000, 0.01, 12);
    let path = est.to_str().unwrap();
    let run = |speed: &str| {
        let j = designed(&[
            "--input",
            path,
            "--offset",
            "intercept",
            "--structure",
            "2,2,2",
            "--control",
            "--json",
            "--speed",
            speed,
        ]);
        let c = &j["control"];
        assert_eq!(c["tries"].as_u64(), Some(1), "{c}");
        assert!((c["tau_s"].as_f64().unwrap() - speed.parse::<f64>().unwrap()).abs() < 1e-12);
        let (r, s, t) = (vec_of(&c["r"]), vec_of(&c["s"]), vec_of(&c["t"]));
        let (rr, y, _) = closed_loop_on(BLOWER, &r, &s, &t, 0.5, 1.0, 400);
        let last = y.len() - 1;
        assert!((y[last] - rr[last]).abs() < 1e-6);
        (crossing(&rr, &y, 0.63), c["alpha"].as_f64().unwrap())
    };
    let (fast, alpha_fast) = run("0.05");
    let (slow, alpha_slow) = run("0.2");
    assert!(alpha_slow > alpha_fast);
    // Designed: y = q^{−d−1} (B/B(1)) (1 − α)/(1 − α q⁻¹) r, so the 63 % point comes about
    // τ/Ts samples after the loop delay: 5 and 20 samples here, plus ~3.4 of delay.
    assert!(
        slow >= fast + 10,
        "63 % at sample {fast} (0.05 s) and {slow} (0.2 s)"
    );
    let step_at = 10;
    for (k, tau_samples) in [(fast, 5.0), (slow, 20.0)] {
        let after = (k - step_at) as f64;
        assert!(
            (after - (tau_samples + 3.4)).abs() < 0.25 * tau_samples + 2.0,
            "63 % after {after} samples, τ = {tau_samples} samples"
        );
    }
}

fn refused(args: &[&str], check: &str, needles: &[&str]) -> Value {
    let out = ridge_id(args);
    assert_eq!(
        out.status.code(),
        Some(REFUSED),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j = stdout_json(&out);
    // The identification is still reported.
    assert!(j["theta"].is_array() && j["estimation"].is_object(), "{j}");
    let c = &j["control"];
    assert_eq!(c["check"], check, "{c}");
    let reason = c["refused"].as_str().unwrap();
    for n in needles {
        assert!(reason.contains(n), "{n:?} not in {reason:?}");
    }
    j
}

#[test]
fn unstable_wrong_sign_and_oscillating_models_are_refused() {
    const UNSTABLE: Plant = Plant {
        theta: &[1.01],
        phi: &[0.2],
        d: 0,
        y_offset: 0.0,
    };
    let p = log("unstable.csv", UNSTABLE, 400, 0.01, 13);
    let path = p.to_str().unwrap();
    let j = refused(
        &["--input", path, "--method", "ols", "--control", "--json"],
        "unstable",
        &["unstable", "outside the radius 0.995", "largest |z| = 1.0"],
    );
    assert_eq!(j["control"]["tries"].as_u64(), Some(0));
    // The readable report says it too, with the same exit status.
    let out = ridge_id(&["--input", path, "--method", "ols", "--control"]);
    assert_eq!(out.status.code(), Some(REFUSED));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("REFUSED") && text.contains("check: unstable"),
        "{text}"
    );
    assert!(
        text.contains("static gain"),
        "identification missing: {text}"
    );

    const NEGATIVE: Plant = Plant {
        theta: &[0.9],
        phi: &[-0.5],
        d: 1,
        y_offset: 10.0,
    };
    let p = log("negative.csv", NEGATIVE, 2000, 0.01, 14);
    let path = p.to_str().unwrap();
    let j = refused(
        &[
            "--input",
            path,
            "--offset",
            "intercept",
            "--control",
            "--json",
        ],
        "gain",
        &["static gain B(1)/A(1) = -", "wrong sign", "above 0"],
    );
    assert_eq!(j["control"]["tries"].as_u64(), Some(0));
    // Allowed explicitly, the same log gets a controller (the design has no sign rule).
    let j = ok_json(&ridge_id(&[
        "--input",
        path,
        "--offset",
        "intercept",
        "--control",
        "--gain-min",
        "-10",
        "--gain-max",
        "-1",
        "--json",
    ]));
    assert_eq!(j["control"]["method"], "pole-placement", "{j}");
    // Size limits in the log's units (e.g. the firmware's 20..2000 slm per unit duty)
    // refuse a gain of ~27 outside them.
    let b = log("blower_gain.csv", BLOWER, 2000, 0.01, 15);
    refused(
        &[
            "--input",
            b.to_str().unwrap(),
            "--offset",
            "intercept",
            "--control",
            "--gain-min",
            "100",
            "--gain-max",
            "2000",
            "--json",
        ],
        "gain",
        &["must be in 100..=2000 (--gain-min, --gain-max)"],
    );

    // A slow complex pair (|z| = 0.84): the design moves only one real slow pole.
    const OSCILLATING: Plant = Plant {
        theta: &[1.5, -0.7],
        phi: &[1.0, 0.5],
        d: 2,
        y_offset: 0.0,
    };
    let p = log("oscillating.csv", OSCILLATING, 2000, 0.01, 16);
    refused(
        &[
            "--input",
            p.to_str().unwrap(),
            "--control",
            "--json",
            "--structure",
            "2,2,2",
        ],
        "slow-poles",
        &["slow model poles", "keep radius 0.8"],
    );
}

#[test]
fn plot_usage_errors_and_degenerate_models() {
    let est = log("plot.csv", BLOWER, 2000, 0.01, 17);
    let path = est.to_str().unwrap();
    let png = tmp("plot.png");
    let step_png = tmp("plot-control.png");
    let _ = fs::remove_file(&step_png);
    let out = ridge_id(&[
        "--input",
        path,
        "--control",
        "--plot",
        png.to_str().unwrap(),
        "--u-step",
        "0.05",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    for needle in [
        "method        pole-placement",
        "R = [1.000000,",
        "closed-loop poles",
        "|z|",
        "closed-loop step plot written to",
    ] {
        assert!(text.contains(needle), "{needle:?} missing from\n{text}");
    }
    let bytes = fs::read(&step_png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert!(bytes.len() > 10_000, "{} bytes", bytes.len());

    // Control options without --control are command-line errors (2); bad values are
    // usage errors (1); neither panics.
    for (args, code) in [
        (vec!["--input", path, "--speed", "0.1"], 2),
        (vec!["--input", path, "--ts", "0.1"], 2),
        (vec!["--input", path, "--control", "--speed", "-1"], 1),
        (vec!["--input", path, "--control", "--speed", "0"], 1),
        (vec!["--input", path, "--control", "--ts", "inf"], 1),
        (vec!["--input", path, "--control", "--ts", "-0.01"], 1),
        (vec!["--input", path, "--control", "--u-step", "-0.1"], 1),
        (vec!["--input", path, "--control", "--observer", "0"], 1),
        (
            vec![
                "--input",
                path,
                "--control",
                "--gain-min",
                "5",
                "--gain-max",
                "1",
            ],
            1,
        ),
        (
            vec![
                "--input",
                path,
                "--control",
                "--u-min",
                "0.9",
                "--u-max",
                "0.1",
            ],
            1,
        ),
        (vec!["--input", path, "--control", "--u-min", "2"], 1),
    ] {
        let out = ridge_id(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(stderr.starts_with("error: "), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }

    // B(1) = 0 (a differentiating input): refused by the gain checks (sign, or size for the
    // log), never a panic.
    const NO_GAIN: Plant = Plant {
        theta: &[0.8],
        phi: &[1.0, -1.0],
        d: 0,
        y_offset: 0.0,
    };
    let p = log("no_gain.csv", NO_GAIN, 2000, 0.0, 18);
    let path = p.to_str().unwrap();
    for extra in [&[][..], &["--gain-min", "-1"][..]] {
        let mut args = vec![
            "--input",
            path,
            "--method",
            "ols",
            "--structure",
            "1,2,0",
            "--offset",
            "intercept",
            "--control",
            "--json",
        ];
        args.extend(extra);
        let out = ridge_id(&args);
        assert_eq!(
            out.status.code(),
            Some(REFUSED),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let j = stdout_json(&out);
        assert_eq!(j["control"]["check"], "gain", "{j}");
        assert_eq!(j["control"]["tries"].as_u64(), Some(0));
    }
}
