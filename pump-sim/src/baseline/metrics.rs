//! Tracking metrics of a sampled response: setpoint steps ([`step_metrics`]), RMS tracking
//! error ([`rms_error`]) and the duty's total variation ([`total_variation`]).
//!
//! # Timing
//! Sample `y[i]` is the flow at the end of interval `i`. A step to `to` that holds from
//! interval `step` on happens at the end of interval `step − 1`, so `y[i]` lies
//! `(i + 1 − step)·Ts` after the step (`y[step]` one sample after it). Samples before `step`
//! belong to the previous level: with a setpoint preview the flow may start to move before the
//! programmed step, and its 10 % crossing is then before time 0.

/// Length of the window at the end of a level over which the steady-state error is averaged,
/// s.
pub const SS_WINDOW_S: f64 = 0.5;

/// Settling band around a final value `to` (slm): ±2 % of it or ±1 slm, whichever is larger.
pub fn settle_band(to: f64) -> f64 {
    (0.02 * to.abs()).max(1.0)
}

/// Metrics of one setpoint step. Flows in slm, times in s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepMetrics {
    /// 10–90 % rise time: from the last crossing of 10 % of the step before the first crossing
    /// of 90 % to that crossing (linear interpolation between samples), the search starting at
    /// the last sample up to the step still below 10 %; `None` when the flow never reaches
    /// 90 % within the level.
    pub rise_s: Option<f64>,
    /// Largest excursion past the final value in the direction of the step, percent of the
    /// step size (0 without overshoot).
    pub overshoot_pct: f64,
    /// Time after the step from which on every sample of the level lies within
    /// [`settle_band`] of the final value; `None` when the last sample is outside.
    pub settling_s: Option<f64>,
    /// Mean of `to − y` over the last [`SS_WINDOW_S`] of the level, slm.
    pub ss_error: f64,
    /// Integral of the error against the program over the level and the `lead` samples
    /// before it: `Σ |r[i] − y[i]| · Ts` with `r` = `from` before the step and `to` from it
    /// on, slm·s.
    pub iae: f64,
}

/// The metrics of a step from `from` to `to` (slm) in `y` (see the module docs for the
/// timing): `y[step..]` is the level, `y[..step]` the end of the previous one, `ts_s` the
/// sample period. The IAE also counts the `lead` samples before the step, against `from`
/// (the program's setpoint there). `None` when the step is empty (`from == to`), the level has
/// no sample, `lead > step`, or a sample is not finite.
pub fn step_metrics(
    y: &[f64],
    step: usize,
    lead: usize,
    from: f64,
    to: f64,
    ts_s: f64,
) -> Option<StepMetrics> {
    let delta = to - from;
    if delta == 0.0 || step >= y.len() || lead > step || y.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let time = |i: f64| (i + 1.0 - step as f64) * ts_s;
    // Progress towards the new level: 0 at `from`, 1 at `to`.
    let g = |v: f64| (v - from) / delta;
    let crossing = |i: usize, level: f64| {
        let (a, b) = (g(y[i]), g(y[i + 1]));
        time(i as f64 + (level - a) / (b - a))
    };
    // The move starts after the last sample up to the step that is below 10 %.
    let rise_s = y[..=step]
        .iter()
        .rposition(|&v| g(v) < 0.1)
        .and_then(|start| {
            let i90 = start + y[start..].iter().position(|&v| g(v) >= 0.9)?;
            let j = y[..i90].iter().rposition(|&v| g(v) < 0.1)?;
            Some(crossing(i90 - 1, 0.9) - crossing(j, 0.1))
        });
    let level = &y[step..];
    let peak = level
        .iter()
        .map(|&v| g(v))
        .fold(f64::NEG_INFINITY, f64::max);
    let overshoot_pct = (100.0 * (peak - 1.0)).max(0.0);
    let band = settle_band(to);
    let settling_s = match level.iter().rposition(|&v| (v - to).abs() > band) {
        None => Some(time(step as f64)),
        Some(i) if i + 1 < level.len() => Some(time((step + i + 1) as f64)),
        Some(_) => None,
    };
    let n = ((SS_WINDOW_S / ts_s).round() as usize).clamp(1, level.len());
    let tail = &level[level.len() - n..];
    let ss_error = tail.iter().map(|&v| to - v).sum::<f64>() / n as f64;
    Some(StepMetrics {
        rise_s,
        overshoot_pct,
        settling_s,
        ss_error,
        iae: step_iae(y, step, lead, from, to, ts_s),
    })
}

/// The IAE of [`StepMetrics::iae`]: `Σ |r[i] − y[i]| · Ts` over `y[step − lead..]`, with
/// `r` = `from` before `step` and `to` from it on, slm·s. Requires `lead ≤ step ≤ y.len()`
/// (samples outside are not counted).
pub fn step_iae(y: &[f64], step: usize, lead: usize, from: f64, to: f64, ts_s: f64) -> f64 {
    let before: f64 = y
        .get(step.saturating_sub(lead)..step)
        .unwrap_or(&[])
        .iter()
        .map(|&v| (from - v).abs())
        .sum();
    let after: f64 = y
        .get(step..)
        .unwrap_or(&[])
        .iter()
        .map(|&v| (to - v).abs())
        .sum();
    (before + after) * ts_s
}

/// RMS of `r − y` over the common length, same units as the inputs; `None` when empty.
pub fn rms_error(y: &[f64], r: &[f64]) -> Option<f64> {
    let n = y.len().min(r.len());
    if n == 0 {
        return None;
    }
    let ss: f64 = y.iter().zip(r).map(|(a, b)| (b - a).powi(2)).sum();
    Some((ss / n as f64).sqrt())
}

/// Total variation of `u` per second: `Σ |u[k] − u[k−1]| / ((len − 1) · ts_s)`, units of `u`
/// per second; `None` with fewer than two samples.
pub fn total_variation(u: &[f64], ts_s: f64) -> Option<f64> {
    if u.len() < 2 {
        return None;
    }
    let tv: f64 = u.windows(2).map(|w| (w[1] - w[0]).abs()).sum();
    Some(tv / ((u.len() - 1) as f64 * ts_s))
}

/// Mean of the values that are present; `None` when none is.
pub fn mean_present(v: impl IntoIterator<Item = Option<f64>>) -> Option<f64> {
    let (s, n) = v
        .into_iter()
        .flatten()
        .fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order step response `Δ (1 − e^{−t/τ})` from `from`, sampled at `ts` with the
    /// step at sample `step` (see the module docs), `n` samples of the level.
    fn first_order(from: f64, delta: f64, tau: f64, ts: f64, step: usize, n: usize) -> Vec<f64> {
        (0..step + n)
            .map(|i| {
                let t = (i as f64 + 1.0 - step as f64) * ts;
                if t <= 0.0 {
                    from
                } else {
                    from + delta * (1.0 - (-t / tau).exp())
                }
            })
            .collect()
    }

    #[test]
    fn first_order_step() {
        // τ = 1 s, Ts = 1 ms, 20 s of level, Δ = 100 slm from 0.
        let (tau, ts) = (1.0, 0.001);
        let y = first_order(0.0, 100.0, tau, ts, 50, 20_000);
        let m = step_metrics(&y, 50, 0, 0.0, 100.0, ts).unwrap();
        // Rise 10–90 %: τ ln 9 (linear interpolation of a convex curve: error ≪ Ts).
        assert!((m.rise_s.unwrap() - tau * 9f64.ln()).abs() < 1e-6, "{m:?}");
        assert_eq!(m.overshoot_pct, 0.0);
        // Band 2 slm (2 % of 100 > 1): e^{−t/τ} ≤ 0.02 from τ ln 50 on, on the sample grid.
        let s = m.settling_s.unwrap();
        assert!(s >= tau * 50f64.ln() && s < tau * 50f64.ln() + ts, "{s}");
        // IAE: right Riemann sum of Δ τ e^{−t/τ}: Δ τ (1 − e^{−T/τ}) · x/(e^x − 1), x = Ts/τ.
        let x = ts / tau;
        let iae = 100.0 * tau * (1.0 - (-20.0f64).exp()) * x / x.exp_m1();
        assert!((m.iae - iae).abs() < 1e-9, "{} vs {iae}", m.iae);
        // Steady state after 20 τ: 100 e^{−20} ≈ 2e−7.
        assert!(m.ss_error.abs() < 1e-6);
    }

    #[test]
    fn downward_step_with_overshoot_and_offset() {
        // 60 → 35 slm (Δ −25), Ts 10 ms, a hand-made trajectory: the step at sample 2.
        // Level: 50, 40, 30 (overshoot 5 slm = 20 %), 34, 36, then 35.5 for 100 samples.
        let mut y = vec![60.0, 60.0, 50.0, 40.0, 30.0, 34.0, 36.0];
        y.extend(std::iter::repeat_n(35.5, 100));
        let m = step_metrics(&y, 2, 0, 60.0, 35.0, 0.01).unwrap();
        // 10 % (57.5) between y[1] = 60 (t 0) and y[2] = 50 (t 0.01): t = 0.0025;
        // 90 % (37.5) between y[3] = 40 (t 0.02) and y[4] = 30 (t 0.03): t = 0.0225.
        assert!((m.rise_s.unwrap() - 0.02).abs() < 1e-12, "{m:?}");
        assert!((m.overshoot_pct - 20.0).abs() < 1e-12);
        // Band 1 slm: y[6] = 36 is within (|36 − 35| = 1), y[5] = 34 too, y[4] = 30 is not:
        // settled from y[5], 4 samples after the step.
        assert!((m.settling_s.unwrap() - 0.04).abs() < 1e-12);
        assert!((m.ss_error - (-0.5)).abs() < 1e-12);
        let iae = (15.0 + 5.0 + 5.0 + 1.0 + 1.0 + 0.5 * 100.0) * 0.01;
        assert!((m.iae - iae).abs() < 1e-12);
        // Two samples of lead: y[0], y[1] = 60 against the old setpoint 60 add nothing;
        // a flow that moved early (59 at y[0]) adds 1 slm for one sample.
        let m2 = step_metrics(&y, 2, 2, 60.0, 35.0, 0.01).unwrap();
        assert!((m2.iae - iae).abs() < 1e-12);
        y[0] = 59.0;
        let m3 = step_metrics(&y, 2, 2, 60.0, 35.0, 0.01).unwrap();
        assert!((m3.iae - iae - 0.01).abs() < 1e-12);
        assert_eq!(m3.rise_s, m.rise_s);
    }

    #[test]
    fn preview_crossing_before_the_step_and_no_settling() {
        // The flow starts before the step (preview) and never settles (last sample out).
        let y = [0.0, 0.0, 15.0, 20.0, 95.0, 100.0, 103.0];
        let m = step_metrics(&y, 3, 0, 0.0, 100.0, 1.0).unwrap();
        // y[i] at t = i − 2. 10 % between y[1] (t −1) and y[2] (t 0): t = −1 + 10/15;
        // 90 % between y[3] (t 1) and y[4] (t 2): t = 1 + 70/75.
        let expect = 1.0 + 70.0 / 75.0 - (-1.0 + 10.0 / 15.0);
        assert!((m.rise_s.unwrap() - expect).abs() < 1e-12, "{m:?}");
        assert!((m.overshoot_pct - 3.0).abs() < 1e-12);
        assert_eq!(m.settling_s, None);
        // Never reaching 90 %: no rise time.
        let m = step_metrics(&[0.0, 50.0, 80.0], 1, 0, 0.0, 100.0, 1.0).unwrap();
        assert_eq!(m.rise_s, None);
        assert_eq!(step_metrics(&[1.0], 0, 0, 5.0, 5.0, 1.0), None);
        assert_eq!(step_metrics(&[1.0, 2.0], 1, 2, 0.0, 5.0, 1.0), None);
        assert_eq!(step_metrics(&[f64::NAN], 0, 0, 0.0, 5.0, 1.0), None);
    }

    #[test]
    fn rms_and_total_variation() {
        assert_eq!(rms_error(&[1.0, 3.0], &[2.0, 2.0]), Some(1.0));
        assert_eq!(rms_error(&[], &[]), None);
        // Square wave 0.3/0.4 switching every sample for 11 samples: 10 changes of 0.1 in
        // 0.1 s → 10 per s.
        let u: Vec<f64> = (0..11)
            .map(|k| if k % 2 == 0 { 0.3 } else { 0.4 })
            .collect();
        assert!((total_variation(&u, 0.01).unwrap() - 10.0).abs() < 1e-9);
        assert_eq!(total_variation(&[1.0], 0.01), None);
        assert_eq!(mean_present([Some(1.0), None, Some(3.0)]), Some(2.0));
        assert_eq!(mean_present([None]), None);
    }
}
