//! Ziegler–Nichols tuning from the ultimate gain `K_u` and period `T_u` of the plant.
//!
//! # How `K_u` and `T_u` are found
//! On the noise-free plant ([`Plant`]: the rig's true flow, no sensor), around an operating
//! point (default 40 slm):
//!
//! 1. **Operating point**: the constant duty `u₀` whose settled flow is the target, by
//!    bisection on the duty (each trial from rest, [`ZnSearch::settle_ticks`] samples); the
//!    plant settled at `u₀` is the start of every trial below.
//! 2. **Proportional loop**: `u_{k+1} = u₀ + K_p (r − y_k)` with `r = y₀ +` a small kick
//!    ([`ZnSearch::kick_slm`]), computed from the reading at the end of one interval and applied
//!    during the next — the timing every controller of the comparison has, so that `K_u` is the
//!    ultimate gain of the loop as the PID will run it (sampling included). The duty is limited
//!    only to the physical 0..1.
//! 3. **Growing or decaying**: the turning points of the flow (with a hysteresis of 5 % of
//!    the kick, above the chatter of the duty's 10⁻⁴ quantisation) give the half-cycle amplitudes; the oscillation grows when the mean of the
//!    last four exceeds the mean of the four after the initial transient (or when the duty
//!    saturates). `K_u` is bracketed by doubling and then bisected
//!    ([`ZnSearch::iterations`] halvings, relative width about 10⁻⁹).
//! 4. **`T_u`**: the mean interval between upward crossings of the mid-range of the flow over
//!    the second half of the trial at the largest decaying gain (linear interpolation between
//!    samples).
//!
//! This is the ultimate gain as Ziegler and Nichols defined it (the proportional gain at the
//! stability limit). A relay test ([`relay_test`], `K_u = 4h/(πa)`) is what one runs on a
//! real rig because it keeps the amplitude bounded, but its describing-function `K_u` is an
//! approximation (the flow is not a sinusoid, and the relay switches only at samples); on the
//! simulator the exact search costs milliseconds, and the relay test is kept as a cross-check.
//!
//! # The classic PID rule
//! `K_p = 0.6 K_u`, `T_i = T_u / 2`, `T_d = T_u / 8` ([`zn_pid`]).

use super::pid::PidGains;
use super::stepped::Plant;

/// Settings of the ultimate-gain search. Flows in slm, durations in samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZnSearch {
    /// Flow of the operating point, slm (default 40).
    pub flow_slm: f64,
    /// Setpoint step that starts the oscillation, slm (default 2).
    pub kick_slm: f64,
    /// Samples a constant duty is held before its flow counts as settled (default 1000 =
    /// 10 s).
    pub settle_ticks: usize,
    /// Samples of each proportional-loop trial (default 2000 = 20 s).
    pub ticks: usize,
    /// Bisection halvings of the gain bracket (default 30).
    pub iterations: usize,
}

impl ZnSearch {
    /// The defaults (see each field).
    pub const DEFAULT: ZnSearch = ZnSearch {
        flow_slm: 40.0,
        kick_slm: 2.0,
        settle_ticks: 1000,
        ticks: 2000,
        iterations: 30,
    };
}

impl Default for ZnSearch {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The ultimate gain and period, and the operating point they were found at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ultimate {
    /// Ultimate gain `K_u`, duty fraction per slm.
    pub ku: f64,
    /// Ultimate period `T_u`, s.
    pub tu_s: f64,
    /// Duty of the operating point, fraction 0..1.
    pub u0: f64,
    /// Settled flow at `u0`, slm.
    pub y0: f64,
}

/// Why the ultimate gain was not found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ZnError {
    /// No duty in 0..1 gives the target flow.
    OperatingPoint,
    /// No gain up to 2³⁰ times the first guess makes the loop oscillate with growing
    /// amplitude, or no period could be read.
    NoOscillation,
}

impl std::fmt::Display for ZnError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ZnError::OperatingPoint => "no duty in 0..1 gives the operating-point flow",
            ZnError::NoOscillation => "the proportional loop does not reach a growing oscillation",
        })
    }
}

impl std::error::Error for ZnError {}

/// The classic Ziegler–Nichols PID: `K_p = 0.6 K_u`, `T_i = T_u / 2`, `T_d = T_u / 8`, derivative
/// filter `N = 10`.
pub fn zn_pid(u: &Ultimate) -> PidGains {
    PidGains::pid(0.6 * u.ku, u.tu_s / 2.0, u.tu_s / 8.0)
}

/// The flow (plant output) after holding duty `u` for `ticks` samples from `plant`'s state.
fn hold<P: Plant + Clone>(plant: &P, u: f64, ticks: usize) -> (P, f64) {
    let mut p = plant.clone();
    let mut y = f64::NAN;
    for _ in 0..ticks {
        y = p.apply(u);
    }
    (p, y)
}

/// The operating point for `flow` (slm): the duty in 0..1 whose flow after `settle_ticks`
/// samples from `plant`'s state is `flow` (bisection; the steady-state flow must rise with the
/// duty), the plant settled there and its flow. `None` when the flow is out of reach.
pub fn operating_point<P: Plant + Clone>(
    plant: &P,
    flow: f64,
    settle_ticks: usize,
) -> Option<(P, f64, f64)> {
    let (mut lo, mut hi) = (0.0, 1.0);
    let (_, y_hi) = hold(plant, hi, settle_ticks);
    let (_, y_lo) = hold(plant, lo, settle_ticks);
    if !(y_lo <= flow && flow <= y_hi) {
        return None;
    }
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if hold(plant, mid, settle_ticks).1 < flow {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let u0 = 0.5 * (lo + hi);
    let (p, y0) = hold(plant, u0, settle_ticks);
    y0.is_finite().then_some((p, u0, y0))
}

/// Turning points `(index, value)` of `y` with hysteresis `eps`: a maximum is recorded once
/// the signal has fallen more than `eps` below it, a minimum likewise.
pub fn turning_points(y: &[f64], eps: f64) -> Vec<(usize, f64)> {
    let mut out = Vec::new();
    let Some(&first) = y.first() else {
        return out;
    };
    // direction: 1 rising, -1 falling, 0 unknown; (index, value) of the running extreme.
    let mut dir = 0i8;
    let (mut hi, mut lo) = ((0usize, first), (0usize, first));
    for (i, &v) in y.iter().enumerate() {
        if v > hi.1 {
            hi = (i, v);
        }
        if v < lo.1 {
            lo = (i, v);
        }
        match dir {
            1 if v < hi.1 - eps => {
                out.push(hi);
                dir = -1;
                lo = (i, v);
            }
            -1 if v > lo.1 + eps => {
                out.push(lo);
                dir = 1;
                hi = (i, v);
            }
            0 if v > lo.1 + eps => {
                dir = 1;
                hi = (i, v);
            }
            0 if v < hi.1 - eps => {
                dir = -1;
                lo = (i, v);
            }
            _ => {}
        }
    }
    out
}

/// One proportional-loop trial: the flows, and whether the duty saturated at 0 or 1 (the
/// trial stops there).
fn p_trial<P: Plant + Clone>(
    settled: &P,
    u0: f64,
    y0: f64,
    kp: f64,
    r: f64,
    ticks: usize,
) -> (Vec<f64>, bool) {
    let mut p = settled.clone();
    let mut y = y0;
    let mut ys = Vec::with_capacity(ticks);
    for _ in 0..ticks {
        let v = u0 + kp * (r - y);
        if !(0.0..=1.0).contains(&v) {
            return (ys, true);
        }
        y = p.apply(v);
        if !y.is_finite() {
            return (ys, true);
        }
        ys.push(y);
    }
    (ys, false)
}

/// Whether the oscillation in `ys` grows (see the module docs); `eps` is the turning-point
/// hysteresis.
fn grows(ys: &[f64], saturated: bool, eps: f64) -> bool {
    if saturated {
        return true;
    }
    let tp = turning_points(ys, eps);
    let amp: Vec<f64> = tp.windows(2).map(|w| (w[1].1 - w[0].1).abs()).collect();
    // Skip the first two half cycles (the step response), then compare 4 with the last 4.
    if amp.len() < 2 + 8 {
        return false;
    }
    let early: f64 = amp[2..6].iter().sum();
    let late: f64 = amp[amp.len() - 4..].iter().sum();
    late > early
}

/// Mean interval (samples) between upward crossings of the mid-range of `y`, from linear
/// interpolation; `None` with fewer than two crossings.
pub fn mean_period(y: &[f64]) -> Option<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in y {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let mid = 0.5 * (lo + hi);
    let mut crossings = Vec::new();
    for (i, w) in y.windows(2).enumerate() {
        if w[0] < mid && w[1] >= mid {
            crossings.push(i as f64 + (mid - w[0]) / (w[1] - w[0]));
        }
    }
    match (crossings.first(), crossings.last()) {
        (Some(a), Some(b)) if crossings.len() >= 2 => Some((b - a) / (crossings.len() - 1) as f64),
        _ => None,
    }
}

/// The ultimate gain and period of `plant` (in its current state, e.g. at rest) around the
/// operating point of `search`, with sample period `ts_s` (see the module docs).
pub fn ultimate<P: Plant + Clone>(
    plant: &P,
    search: &ZnSearch,
    ts_s: f64,
) -> Result<Ultimate, ZnError> {
    let (settled, u0, y0) = operating_point(plant, search.flow_slm, search.settle_ticks)
        .ok_or(ZnError::OperatingPoint)?;
    let r = y0 + search.kick_slm;
    let eps = 0.05 * search.kick_slm.abs();
    let trial = |kp: f64| p_trial(&settled, u0, y0, kp, r, search.ticks);
    let grows_at = |kp: f64| {
        let (ys, sat) = trial(kp);
        grows(&ys, sat, eps)
    };
    // First guess: the gain that moves the duty by 1 % per slm.
    let mut lo = 0.0;
    let mut hi = 0.01;
    let mut found = false;
    for _ in 0..30 {
        if grows_at(hi) {
            found = true;
            break;
        }
        lo = hi;
        hi *= 2.0;
    }
    if !found {
        return Err(ZnError::NoOscillation);
    }
    for _ in 0..search.iterations {
        let mid = 0.5 * (lo + hi);
        if grows_at(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let ku = 0.5 * (lo + hi);
    let (ys, _) = trial(lo);
    let half = &ys[ys.len() / 2..];
    let period = mean_period(half).ok_or(ZnError::NoOscillation)?;
    Ok(Ultimate {
        ku,
        tu_s: period * ts_s,
        u0,
        y0,
    })
}

/// A relay test around the operating point of `search`: `u = u₀ ± h` (duty fraction) switched
/// on the sign of `y₀ − y`, for [`ZnSearch::ticks`] samples; from the second half, `a` = half
/// the peak-to-peak flow, `T_u` = the mean period, `K_u = 4h / (π a)` (describing function).
/// An approximation of [`ultimate`], kept as a cross-check.
pub fn relay_test<P: Plant + Clone>(
    plant: &P,
    search: &ZnSearch,
    h: f64,
    ts_s: f64,
) -> Result<Ultimate, ZnError> {
    let (mut p, u0, y0) = operating_point(plant, search.flow_slm, search.settle_ticks)
        .ok_or(ZnError::OperatingPoint)?;
    let mut y = y0;
    let mut ys = Vec::with_capacity(search.ticks);
    for _ in 0..search.ticks {
        let u = if y < y0 { u0 + h } else { u0 - h };
        y = p.apply(u.clamp(0.0, 1.0));
        ys.push(y);
    }
    let half = &ys[ys.len() / 2..];
    let (lo, hi) = half
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    let a = 0.5 * (hi - lo);
    let period = mean_period(half).ok_or(ZnError::NoOscillation)?;
    if a.is_nan() || a <= 0.0 {
        return Err(ZnError::NoOscillation);
    }
    Ok(Ultimate {
        ku: 4.0 * h / (std::f64::consts::PI * a),
        tu_s: period * ts_s,
        u0,
        y0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turning_points_of_a_sampled_sine() {
        let y: Vec<f64> = (0..100)
            .map(|i| (2.0 * std::f64::consts::PI * i as f64 / 20.0).sin())
            .collect();
        let tp = turning_points(&y, 0.01);
        // Maxima at 5, 25, …, minima at 15, 35, …; the last minimum is confirmed at 96.
        let idx: Vec<usize> = tp.iter().map(|t| t.0).collect();
        assert_eq!(idx, vec![5, 15, 25, 35, 45, 55, 65, 75, 85, 95]);
        assert!((mean_period(&y).unwrap() - 20.0).abs() < 1e-9);
    }

    #[test]
    fn zn_rule() {
        let g = zn_pid(&Ultimate {
            ku: 0.05,
            tu_s: 0.2,
            u0: 0.4,
            y0: 40.0,
        });
        assert_eq!((g.kp, g.ti_s, g.td_s, g.n), (0.03, 0.1, 0.025, 10.0));
    }
}
