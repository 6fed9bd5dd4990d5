//! The controller design (`ridge_core::control`) against independent truth: closed-loop poles
//! as eigenvalues of the companion matrix of `A R + q^{−d−1} B S` (nalgebra), the modulus
//! margin against a dense complex frequency sweep, and closed-loop simulations of ARX plants
//! (offset steps, gain errors, saturation and recovery, rate limit, bumpless start), plus the
//! refusals.

use nalgebra::{Complex, DMatrix};
use ridge_core::control::{
    check_model, design, design_slower_on_failure, Controller, Design, DesignError, Limits,
    ModelFault, ModelLimits, Spec,
};
use ridge_core::{ArxModel, Offset};

const TS: f64 = 0.01;

/// Models of the three simulated blowers as the pump identifies them (physical units: slm per
/// duty fraction), and two textbook plants.
fn plants() -> Vec<(&'static str, ArxModel<f64>)> {
    let m = |th: &[f64], ph: &[f64], d: u8| ArxModel::new(th, ph, d, Offset::None, 0.0).unwrap();
    vec![
        (
            "default pump",
            m(
                &[0.156584, 0.226205, 0.1695, 0.172856, 0.110657],
                &[10.50556, 9.86167, 8.116505],
                3,
            ),
        ),
        (
            "small pump",
            m(
                &[0.169198, 0.222333, 0.155929, 0.148679, 0.065312],
                &[12.771555, 11.326143, 9.188023],
                2,
            ),
        ),
        (
            "sluggish pump",
            m(
                &[0.149351, 0.214363, 0.154896, 0.175882, 0.14163, 0.083943],
                &[8.917463, 8.002105],
                6,
            ),
        ),
        ("first order, no delay", m(&[0.9], &[0.5], 0)),
        // Real poles 0.9 and 0.5, a zero outside the unit circle (at −1.5).
        (
            "second order, zero outside",
            m(&[1.4, -0.45], &[1.0, 1.5], 1),
        ),
    ]
}

fn a_poly(m: &ArxModel<f64>) -> Vec<f64> {
    std::iter::once(1.0)
        .chain(m.theta().iter().map(|t| -t))
        .collect()
}

fn conv(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// `A R + q^{−d−1} B S`, computed here independently of the design.
fn closed_loop(m: &ArxModel<f64>, r: &[f64], s: &[f64]) -> Vec<f64> {
    let ar = conv(&a_poly(m), r);
    let mut b1 = vec![0.0; usize::from(m.structure().d) + 1];
    b1.extend_from_slice(m.phi());
    let bs = conv(&b1, s);
    let n = ar.len().max(bs.len());
    (0..n)
        .map(|k| ar.get(k).unwrap_or(&0.0) + bs.get(k).unwrap_or(&0.0))
        .collect()
}

/// Roots of `p₀zⁿ + p₁zⁿ⁻¹ + … + pₙ` as the eigenvalues of its companion matrix.
fn roots(p: &[f64]) -> Vec<Complex<f64>> {
    let mut p = p.to_vec();
    while p.len() > 1 && p.last() == Some(&0.0) {
        p.pop();
    }
    let n = p.len() - 1;
    if n == 0 {
        return vec![];
    }
    let mut c = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        c[(0, j)] = -p[j + 1] / p[0];
    }
    for i in 1..n {
        c[(i, i - 1)] = 1.0;
    }
    let mut r: Vec<Complex<f64>> = c.complex_eigenvalues().iter().copied().collect();
    // Roots dropped with trailing zero coefficients are at the origin.
    r.resize(r.len(), Complex::new(0.0, 0.0));
    r
}

/// Dense sweep of `1 / max |AR / P|` over 200 001 frequencies, complex arithmetic.
fn dense_margin(ar: &[f64], p: &[f64]) -> f64 {
    let eval = |c: &[f64], w: f64| {
        let z = Complex::new(0.0, -w).exp();
        c.iter()
            .rev()
            .fold(Complex::new(0.0, 0.0), |acc, &ck| acc * z + ck)
    };
    let n = 200_000;
    (0..=n)
        .map(|k| {
            let w = std::f64::consts::PI * k as f64 / n as f64;
            (eval(ar, w) / eval(p, w)).norm()
        })
        .fold(0.0, f64::max)
        .recip()
}

/// The default design, slowed down until it passes (the textbook plant with a zero outside
/// the unit circle needs it).
fn designed(name: &str, m: &ArxModel<f64>) -> ridge_core::control::Design<f64> {
    design_slower_on_failure(m, &Spec::new(TS), 6, 1.5, || {})
        .0
        .unwrap_or_else(|e| panic!("{name}: {e:?}"))
}

#[test]
fn closed_loop_poles_are_the_designed_ones() {
    for (name, m) in plants() {
        let d = designed(name, &m);
        let rst = d.rst;
        // Integral action and unit static gain.
        let r1: f64 = rst.r().iter().sum();
        assert!(r1.abs() < 1e-9, "{name}: R(1) = {r1}");
        let (s1, t1): (f64, f64) = (rst.s().iter().sum(), rst.t().iter().sum());
        assert!(
            (s1 - t1).abs() <= 1e-9 * s1.abs().max(1.0),
            "{name}: S(1) {s1} T(1) {t1}"
        );
        // The closed loop, built here from A, B, R and S.
        let p = closed_loop(&m, rst.r(), rst.s());
        // Its roots: α, β, the model's fast poles, the rest at the origin.
        let mut want = vec![Complex::new(d.alpha, 0.0), Complex::new(d.beta, 0.0)];
        if d.kept > 0 {
            let a = a_poly(&m);
            let all = roots(&a);
            let dom = all
                .iter()
                .filter(|z| z.im.abs() < 1e-9)
                .max_by(|x, y| x.re.total_cmp(&y.re))
                .unwrap();
            want.extend(all.iter().filter(|z| (*z - dom).norm() > 1e-9));
            assert_eq!(want.len(), 2 + usize::from(d.kept), "{name}");
        }
        let got = roots(&p);
        let mut unmatched = got.clone();
        for w in &want {
            let (i, dist) = unmatched
                .iter()
                .enumerate()
                .map(|(i, z)| (i, (z - w).norm()))
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .unwrap();
            assert!(
                dist < 1e-6,
                "{name}: designed pole {w} missing, nearest at {dist}"
            );
            unmatched.remove(i);
        }
        // The others are a repeated root at 0: their computed values scatter around it by
        // about (rounding)^(1/multiplicity).
        for z in &unmatched {
            assert!(z.norm() < 0.05, "{name}: extra pole {z} (all: {got:?})");
        }
        assert!(
            got.iter().all(|z| z.norm() < 1.0),
            "{name}: unstable closed loop"
        );
    }
}

#[test]
fn modulus_margin_agrees_with_a_dense_sweep() {
    for (name, m) in plants() {
        for slower in [1.0, 1.5, 3.0] {
            let spec = Spec {
                min_margin: 0.0,
                ..Spec::new(TS).slower(slower)
            };
            let d = design(&m, &spec).unwrap();
            let ar = conv(&a_poly(&m), d.rst.r());
            let truth = dense_margin(&ar, &closed_loop(&m, d.rst.r(), d.rst.s()));
            // The sweep samples the peak (32 coarse, 17 fine points): within 5e-4 relative,
            // 0.0003 at the 0.5 the design requires.
            assert!(
                (d.modulus_margin - truth).abs() <= 5e-4 * truth,
                "{name} ×{slower}: {} vs dense {truth}",
                d.modulus_margin
            );
        }
    }
}

#[test]
fn default_designs_of_the_pumps_meet_the_margin() {
    for (name, m) in plants().into_iter().take(3) {
        let d = design(&m, &Spec::new(TS)).unwrap();
        assert!(d.modulus_margin >= 0.55, "{name}: {}", d.modulus_margin);
        assert!(d.kept > 0, "{name}: the fast poles are kept");
    }
}

/// The device designs in `f32`: the same controller to 1e-3.
#[test]
fn f32_design_matches_f64() {
    for (name, m) in plants() {
        let m32 = ArxModel::<f32>::new(
            &m.theta().iter().map(|&x| x as f32).collect::<Vec<_>>(),
            &m.phi().iter().map(|&x| x as f32).collect::<Vec<_>>(),
            m.structure().d,
            Offset::None,
            0.0,
        )
        .unwrap();
        let d64 = designed(name, &m);
        let d32 = design(&m32, &Spec::new(TS as f32).slower(d64.spec.slowdown as f32))
            .unwrap_or_else(|e| panic!("{name}: f32 {e:?}"));
        for (a, b) in [
            (d64.rst.r(), d32.rst.r()),
            (d64.rst.s(), d32.rst.s()),
            (&d64.rst.t()[..], &d32.rst.t()[..]),
        ] {
            let scale = a.iter().fold(1e-3f64, |s, x| s.max(x.abs()));
            for (x, y) in a.iter().zip(b) {
                assert!(
                    (x - f64::from(*y)).abs() <= 2e-3 * scale,
                    "{name}: {a:?} vs {b:?}"
                );
            }
        }
        assert!((d64.modulus_margin - f64::from(d32.modulus_margin)).abs() < 2e-3);
    }
}

/// An ARX plant `A y = q^{−d} B u + c` (with the gain of `B` scaled by `gain`).
struct Plant {
    a: Vec<f64>,
    b: Vec<f64>,
    d: usize,
    c: f64,
    y: Vec<f64>,
    u: Vec<f64>,
}

impl Plant {
    fn new(m: &ArxModel<f64>, gain: f64, c: f64, u0: f64) -> Self {
        let a = a_poly(m);
        let mut p = Plant {
            b: m.phi().iter().map(|x| x * gain).collect(),
            d: usize::from(m.structure().d),
            c,
            y: vec![0.0; a.len()],
            u: vec![u0; 32],
            a,
        };
        // Start at the equilibrium of u0.
        let y0 = (p.b.iter().sum::<f64>() * u0 + c) / p.a.iter().sum::<f64>();
        p.y = vec![y0; p.a.len()];
        p
    }

    /// Applies `u` for one interval; returns the reading at its end.
    fn step(&mut self, u: f64) -> f64 {
        self.u.insert(0, u);
        self.u.pop();
        let mut y = self.c;
        for (ai, yi) in self.a.iter().skip(1).zip(&self.y) {
            y -= ai * yi;
        }
        for (j, bj) in self.b.iter().enumerate() {
            y += bj * self.u[self.d + j];
        }
        self.y.insert(0, y);
        self.y.pop();
        y
    }
}

/// Runs `ticks` of the loop; `r(t)` is the setpoint for the interval ending at `t + 1`.
fn run(
    ctrl: &mut Controller<f64>,
    plant: &mut Plant,
    ticks: usize,
    r: impl Fn(usize) -> f64,
    disturb: impl Fn(usize, &mut Plant),
) -> (Vec<f64>, Vec<f64>) {
    let mut ys = Vec::new();
    let mut us = Vec::new();
    let mut u = ctrl.last();
    for t in 0..ticks {
        disturb(t, plant);
        let y = plant.step(u);
        ys.push(y);
        u = ctrl.step(r(t + 1), y);
        us.push(u);
    }
    (ys, us)
}

fn wide() -> Limits<f64> {
    Limits {
        min: -1e9,
        max: 1e9,
        max_step: 1e9,
    }
}

/// The default design with the setpoint's reference model of time constant `reference` (s),
/// its pole `e^{−Ts/τ}` computed here with std's `exp`.
fn design_with_reference(m: &ArxModel<f64>, reference: Option<f64>) -> Design<f64> {
    let mut d = design(m, &Spec::new(TS)).unwrap();
    if let Some(tau) = reference {
        d.set_reference((-TS / tau).exp()).unwrap();
    }
    d
}

/// Without limits the running controller (histories in rings, `T = t₀ A_o` folded into the
/// observer terms, the reference model) is the plain difference equation
/// `R u_{t+1} = T r'_{t+1} − S y_t` of its polynomials, evaluated here directly over the whole
/// history, with `r'` the setpoint through the reference model computed here from its
/// definition (`r_m,t+1 = γ r_m,t + (1 − γ) r_{t+1}`, `r' = (r_m,t+1 − α r_m,t) / (1 − α)`), and
/// without a reference model `r' = r`.
#[test]
fn unlimited_controller_is_the_rst_difference_equation() {
    for reference in [None, Some(0.08), Some(0.02)] {
        for (name, m) in plants() {
            let d = design_with_reference(&m, reference);
            let t_p = d.rst.t();
            let (r_p, s_p) = (d.rst.r(), d.rst.s());
            let want = reference.map(|tau: f64| (-TS / tau).exp());
            let got = d.rst.reference_pole();
            assert_eq!(got.is_some(), want.is_some(), "{name}: γ {got:?}");
            let gamma = got.unwrap_or(0.0);
            assert!(
                (gamma - want.unwrap_or(0.0)).abs() < 1e-12,
                "{name}: γ {gamma}, e^(−Ts/τ) {want:?}"
            );
            let alpha = d.alpha;
            let mut ctrl = Controller::new(d.rst, wide());
            let (u0, y0) = (0.4, 30.0);
            ctrl.start(u0, y0);
            // Histories padded with the start values (the controller's bumpless start).
            let pad = 16;
            let (mut us, mut ys, mut rs) = (vec![u0; pad], vec![y0; pad], vec![y0; pad]);
            let mut rm = y0;
            for t in 0..300usize {
                // Arbitrary bounded inputs: a pseudo-random reading and a stepping setpoint.
                let y = y0 + 5.0 * ((t * 7919 % 101) as f64 / 50.0 - 1.0);
                let r = y0 + if (t / 40) % 2 == 0 { 10.0 } else { -8.0 };
                ys.push(y);
                let shaped = match reference {
                    Some(_) => {
                        let next = gamma * rm + (1.0 - gamma) * r;
                        let shaped = (next - alpha * rm) / (1.0 - alpha);
                        rm = next;
                        shaped
                    }
                    None => r,
                };
                rs.push(shaped);
                let u = ctrl.step(r, y);
                let n = us.len();
                // R(q⁻¹) u_{t+1} with u_{t+1} = u, the others from the history.
                let lhs = u + (1..r_p.len()).map(|k| r_p[k] * us[n - k]).sum::<f64>();
                let rhs = (0..t_p.len())
                    .map(|k| t_p[k] * rs[rs.len() - 1 - k])
                    .sum::<f64>()
                    - (0..s_p.len())
                        .map(|k| s_p[k] * ys[ys.len() - 1 - k])
                        .sum::<f64>();
                assert!(
                    (lhs - rhs).abs() <= 1e-9 * (1.0 + rhs.abs()),
                    "{name} {reference:?} t={t}: R u = {lhs}, T r' − S y = {rhs}"
                );
                us.push(u);
            }
        }
    }
}

/// On the exact model the setpoint response is the designed one, sample by sample:
/// `y = y₀ + q^{−d−1} (B / B(1)) (1 − γ) / (1 − γ q⁻¹) Δr`, computed here from the model's
/// coefficients, with `γ = α` without a reference model and `γ = e^{−Ts/τ_ref}` with one
/// (the regulation loop's `α` cancelled).
#[test]
fn setpoint_response_is_the_designed_first_order_one() {
    for reference in [None, Some(0.08), Some(0.15)] {
        for (name, m) in plants() {
            let d = design_with_reference(&m, reference);
            let want = reference.map_or(d.alpha, |tau: f64| (-TS / tau).exp());
            assert!(
                (d.gamma - want).abs() < 1e-9,
                "{name}: γ {}, want {want}",
                d.gamma
            );
            let gamma = d.gamma;
            let mut plant = Plant::new(&m, 1.0, -5.0, 0.3);
            let y0 = plant.y[0];
            let mut ctrl = Controller::new(d.rst, wide());
            ctrl.start(0.3, y0);
            let step = 20.0;
            let (ys, _) = run(
                &mut ctrl,
                &mut plant,
                200,
                |t| if t >= 1 { y0 + step } else { y0 },
                |_, _| {},
            );
            // The first-order reference, from the step at t = 1.
            let mut first = vec![0.0; 200];
            for t in 1..200 {
                first[t] = gamma * first[t - 1] + (1.0 - gamma) * step;
            }
            let (phi, dd) = (m.phi(), usize::from(m.structure().d));
            let b1: f64 = phi.iter().sum();
            for (t, &y) in ys.iter().enumerate() {
                // ys[t] is the reading that ends interval t; the setpoint r(t) entered the
                // controller one reading earlier (`run` gives it r(t + 1) after ys[t]).
                let want = y0
                    + phi
                        .iter()
                        .enumerate()
                        .map(|(j, p)| {
                            let k = t as i64 - dd as i64 - j as i64;
                            p / b1 * if k >= 0 { first[k as usize] } else { 0.0 }
                        })
                        .sum::<f64>();
                assert!(
                    (y - want).abs() < 1e-6 * step,
                    "{name} {reference:?} t={t}: y {y}, designed {want}"
                );
            }
        }
    }
}

#[test]
fn setpoint_response_is_first_order_without_overshoot_and_offset_steps_leave_no_error() {
    for (name, m) in plants().into_iter().take(3) {
        let d = design(&m, &Spec::new(TS)).unwrap();
        let mut plant = Plant::new(&m, 1.0, -5.0, 0.3);
        let y0 = plant.y[0];
        let mut ctrl = Controller::new(d.rst, wide());
        ctrl.start(0.3, y0);
        let target = y0 + 20.0;
        let delay = usize::from(m.structure().d) + 1;
        let (ys, _) = run(
            &mut ctrl,
            &mut plant,
            600,
            |t| if t >= 1 { target } else { y0 },
            // A step of the plant's offset (a leak, a sensor zero shift) at 3 s.
            |t, p| {
                if t == 300 {
                    p.c += 4.0;
                }
            },
        );
        // Before the disturbance: the designed first-order response after the loop delay.
        let overshoot = ys[..300].iter().fold(f64::MIN, |a, &b| a.max(b)) - target;
        assert!(overshoot < 0.01 * 20.0, "{name}: overshoot {overshoot}");
        // The setpoint response's time constant: the reference model's.
        let tau_samples = -1.0 / d.gamma.ln();
        let t63 = ys.iter().position(|&y| y - y0 >= 0.632 * 20.0).unwrap();
        assert!(
            (t63 as f64) <= delay as f64 + tau_samples + 3.0,
            "{name}: 63 % at {t63}, delay {delay} + τ {tau_samples}"
        );
        assert!((ys[299] - target).abs() < 1e-6, "{name}: {}", ys[299]);
        // After the offset step: back on the setpoint, no steady-state error.
        assert!((ys[300] - target).abs() > 1.0, "{name}: the step is seen");
        assert!((ys[599] - target).abs() < 1e-6, "{name}: {}", ys[599]);
    }
}

#[test]
fn gain_errors_of_a_factor_two_are_tolerated() {
    for (name, m) in plants().into_iter().take(3) {
        let d = design(&m, &Spec::new(TS)).unwrap();
        for gain in [0.5, 2.0] {
            let mut plant = Plant::new(&m, gain, 0.0, 0.3);
            let y0 = plant.y[0];
            let mut ctrl = Controller::new(d.rst, wide());
            ctrl.start(0.3, y0);
            let (ys, _) = run(&mut ctrl, &mut plant, 1500, |_| y0 + 10.0, |_, _| {});
            let tail = &ys[1000..];
            let worst = tail
                .iter()
                .fold(0.0f64, |a, &y| a.max((y - y0 - 10.0).abs()));
            assert!(worst < 1e-3, "{name} gain ×{gain}: error {worst}");
        }
    }
}

#[test]
fn saturation_then_recovery_without_windup() {
    // Without and with the firmware's reference model (0.08 s), which holds while the output
    // is at the limit the setpoint pulls towards.
    for reference in [None, Some(0.08)] {
        saturation_then_recovery(reference);
    }
}

fn saturation_then_recovery(reference: Option<f64>) {
    let (name, m) = plants().remove(0);
    let d = design_with_reference(&m, reference);
    let limits = Limits {
        min: 0.0,
        max: 0.5,
        max_step: 1.0,
    };
    // Reference: the same setpoint change inside the limits (linear response).
    let settle = |ys: &[f64], from: usize, target: f64| {
        from + ys[from..]
            .iter()
            .position(|&y| (y - target).abs() < 0.02 * 20.0)
            .unwrap()
    };
    let mut plant = Plant::new(&m, 1.0, 0.0, 0.3);
    let y0 = plant.y[0];
    let mut ctrl = Controller::new(d.rst, limits);
    ctrl.start(0.3, y0);
    let (lin, _) = run(&mut ctrl, &mut plant, 300, |_| y0 + 20.0, |_, _| {});
    let linear_settle = settle(&lin, 0, y0 + 20.0);
    // Now ask for far more than the duty can give for 2 s (saturated at 0.5 all along),
    // then come back to a reachable setpoint.
    let mut plant = Plant::new(&m, 1.0, 0.0, 0.3);
    let mut ctrl = Controller::new(d.rst, limits);
    ctrl.start(0.3, y0);
    let unreachable = y0 + 500.0;
    let (ys, us) = run(
        &mut ctrl,
        &mut plant,
        600,
        |t| if t < 200 { unreachable } else { y0 + 20.0 },
        |_, _| {},
    );
    assert!(us[50..199].iter().all(|&u| u == 0.5), "{name}: saturated");
    let y_sat = ys[199];
    // Recovery: from the saturated flow down to the new setpoint as fast as the linear loop
    // comes up to it, within a few samples: a wound-up integrator would hold the duty at the
    // limit for about as long as it was saturated.
    let recovered = settle(&ys, 200, y0 + 20.0) - 200;
    assert!(
        recovered <= linear_settle + 15,
        "{name}: recovered after {recovered} samples (linear {linear_settle}), from {y_sat}"
    );
    let undershoot = ys[200..].iter().fold(f64::MAX, |a, &b| a.min(b)) - (y0 + 20.0);
    assert!(undershoot > -2.0, "{name}: undershoot {undershoot}");
}

#[test]
fn rate_limit_bounds_every_step_and_start_is_bumpless() {
    let (_, m) = plants().remove(0);
    let d = design(&m, &Spec::new(TS)).unwrap();
    let limits = Limits {
        min: 0.0,
        max: 1.0,
        max_step: 0.01,
    };
    let mut plant = Plant::new(&m, 1.0, 0.0, 0.3);
    let y0 = plant.y[0];
    let mut ctrl = Controller::new(d.rst, limits);
    ctrl.start(0.3, y0);
    // Bumpless: holding the operating point gives the operating point's duty.
    assert!((ctrl.step(y0, y0) - 0.3).abs() < 1e-12);
    let (_, us) = run(&mut ctrl, &mut plant, 400, |_| y0 + 40.0, |_, _| {});
    let mut prev = 0.3;
    for &u in &us {
        assert!((u - prev).abs() <= 0.01 + 1e-12, "{prev} → {u}");
        prev = u;
    }
    assert!(us.iter().any(|&u| u > 0.45), "the duty did move");
}

/// `output`, the limits applied by the caller, then `commit` is `step`: bit for bit, through
/// saturation, the rate limit, a NaN reading (the previous input held) and the reference
/// model's hold at a limit. (`step` itself is checked against the RST difference equation
/// and closed loops above.)
#[test]
fn output_then_commit_is_step() {
    for reference in [None, Some(0.08)] {
        let (_, m) = plants().remove(0);
        let d = design_with_reference(&m, reference);
        let limits = Limits {
            min: 0.15,
            max: 0.6,
            max_step: 0.03,
        };
        let mut whole = Controller::new(d.rst, limits);
        let mut split = Controller::new(d.rst, limits);
        whole.start(0.3, 20.0);
        split.start(0.3, 20.0);
        for t in 0..400usize {
            let y = if t == 150 {
                f64::NAN
            } else {
                20.0 + 15.0 * ((t * 7919 % 101) as f64 / 50.0 - 1.0)
            };
            // Steps up to beyond what the limit can give, and down.
            let r = [20.0, 300.0, 5.0, 40.0][(t / 60) % 4];
            let a = whole.step(r, y);
            let last = split.last();
            let v = split.output(r, y);
            let b = if v.is_finite() {
                v.clamp(
                    (last - limits.max_step).max(limits.min),
                    (last + limits.max_step).min(limits.max),
                )
            } else {
                last
            };
            split.commit(b);
            assert_eq!(a.to_bits(), b.to_bits(), "tick {t}: {a} {b}");
            // Debug, not ==: a NaN reading stays in both histories, and NaN != NaN.
            assert_eq!(format!("{whole:?}"), format!("{split:?}"), "tick {t}");
        }
    }
}

fn limits() -> ModelLimits<f64> {
    ModelLimits {
        stable_radius: 0.995,
        gain_min: 10.0,
        gain_max: 2000.0,
    }
}

#[test]
fn refusals() {
    let m = |th: &[f64], ph: &[f64], d: u8| ArxModel::new(th, ph, d, Offset::None, 0.0).unwrap();
    // The pumps pass, with their static gain Σφ / (1 − Σθ).
    for (name, pm) in plants().into_iter().take(3) {
        let gain = pm.phi().iter().sum::<f64>() / (1.0 - pm.theta().iter().sum::<f64>());
        match check_model(&pm, &limits()) {
            Ok(g) => assert!(
                (g - gain).abs() <= 1e-9 * gain.abs(),
                "{name}: {g} vs {gain}"
            ),
            Err(e) => panic!("{name}: {e:?}"),
        }
    }
    // Unstable (pole at 1.1), marginal (pole at 0.999), integrating.
    assert_eq!(
        check_model(&m(&[1.1], &[1.0], 0), &limits()),
        Err(ModelFault::Unstable)
    );
    assert_eq!(
        check_model(&m(&[0.999], &[1.0], 0), &limits()),
        Err(ModelFault::Unstable)
    );
    assert_eq!(
        check_model(&m(&[0.5, 0.5], &[1.0], 0), &limits()),
        Err(ModelFault::Unstable)
    );
    // Wrong sign, tiny, huge gain.
    for (ph, gain) in [(-10.0, -100.0), (0.05, 0.5), (500.0, 5000.0)] {
        match check_model(&m(&[0.9], &[ph], 1), &limits()) {
            Err(ModelFault::Gain { gain: g }) => assert!((g - gain).abs() < 1e-9, "{g}"),
            other => panic!("gain {gain}: {other:?}"),
        }
    }
    // Not controllable: B has the slow root of A (a common factor): the slow pole cannot be
    // moved, the Diophantine is singular.
    let common = m(&[1.4, -0.45], &[1.0, -0.9], 0); // A = (1 − 0.9q⁻¹)(1 − 0.5q⁻¹)
    assert_eq!(design(&common, &Spec::new(TS)), Err(DesignError::Singular));
    // A setpoint response far too fast for a long delay: the margin is refused, and slower
    // designs are tried until one passes.
    let sluggish = plants().remove(2).1;
    let greedy = Spec {
        tau: Some(0.01),
        observer: 0.01,
        ..Spec::new(TS)
    };
    match design(&sluggish, &greedy) {
        Err(DesignError::Margin { margin }) => assert!(margin < 0.5, "{margin}"),
        other => panic!("{other:?}"),
    }
    let (slower, tries) = design_slower_on_failure(&sluggish, &greedy, 8, 1.5, || {});
    let slower = slower.unwrap();
    assert!(
        tries > 1 && slower.modulus_margin >= 0.5,
        "{tries} {slower:?}"
    );
    assert!(slower.tau > 0.01 && slower.spec.slowdown > 1.0);
    let (refused, tries) = design_slower_on_failure(&sluggish, &greedy, 1, 1.5, || {});
    assert!(matches!(refused, Err(DesignError::Margin { .. })) && tries == 1);
    // Slow complex poles (0.9 ± 0.3j, an oscillating plant): this design moves real poles only.
    let oscillating = m(&[1.8, -0.9], &[1.0], 1);
    assert_eq!(
        design(&oscillating, &Spec::new(TS)),
        Err(DesignError::SlowPoles)
    );
    // The slow poles are the model's, whatever the speed: one design, not a slower retry.
    let (refused, tries) = design_slower_on_failure(&oscillating, &Spec::new(TS), 5, 1.5, || {});
    assert_eq!((refused, tries), (Err(DesignError::SlowPoles), 1));
    // Nonsense settings.
    let bad = Spec {
        tau: Some(f64::NAN),
        ..Spec::new(TS)
    };
    assert_eq!(design(&sluggish, &bad), Err(DesignError::Spec));
}

/// The Schur–Cohn test against the companion-matrix eigenvalues, on 2000 random polynomials
/// of degree 1..=18, and the dominant real root against them too.
#[test]
fn root_tests_agree_with_eigenvalues() {
    use ridge_core::control::poly::{dominant_real_root, roots_within};
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    let mut rnd = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut checked = (0, 0);
    for _ in 0..2000 {
        let n = 1 + ((rnd() + 1.0) * 9.0) as usize % 18;
        // Roots at random radii: the product of (1 − z_i q⁻¹), real roots and conjugate pairs.
        let mut p = vec![1.0];
        let mut k = 0;
        while k < n {
            let rad = (rnd() + 1.0) * 0.6;
            if k + 1 < n && rnd() > 0.0 {
                let th = rnd() * std::f64::consts::PI;
                p = conv(&p, &[1.0, -2.0 * rad * th.cos(), rad * rad]);
                k += 2;
            } else {
                p = conv(&p, &[1.0, -rad * rnd().signum()]);
                k += 1;
            }
        }
        let rmax = roots(&p).iter().map(|z| z.norm()).fold(0.0, f64::max);
        for radius in [0.5, 0.8, 1.0, 1.1] {
            if (rmax - radius).abs() < 1e-6 {
                continue;
            }
            assert_eq!(
                roots_within(&p, radius),
                rmax < radius,
                "{p:?} radius {radius}"
            );
            checked.0 += 1;
        }
        let reals: Vec<f64> = roots(&p)
            .iter()
            .filter(|z| z.im.abs() < 1e-9 && z.re > 0.0 && z.re < 1.0)
            .map(|z| z.re)
            .collect();
        if let (Some(z), true) = (dominant_real_root(&p), rmax < 1.0) {
            let best = reals.iter().fold(0.0f64, |a, &b| a.max(b));
            assert!((z - best).abs() < 1e-6, "{p:?}: {z} vs {reals:?}");
            checked.1 += 1;
        }
    }
    assert!(checked.0 > 6000 && checked.1 > 300, "{checked:?}");
}

#[test]
fn exp_neg_matches_the_exponential() {
    use ridge_core::control::exp_neg;
    for k in 0..=2000 {
        let x = k as f64 * 0.0025; // 0 ..= 5
        let (got, want) = (exp_neg(x), (-x).exp());
        assert!(
            (got - want).abs() <= 2e-8 * want,
            "x = {x}: {got} vs {want}"
        );
        let got32 = exp_neg(x as f32);
        // f32: each squaring doubles the rounding error (2^7 ulp at x = 5).
        assert!(
            (f64::from(got32) - want).abs() <= 2e-5 * want,
            "x = {x}: f32 {got32}"
        );
    }
    assert!(exp_neg(-1.0f64).is_nan() && exp_neg(f64::NAN).is_nan());
}
