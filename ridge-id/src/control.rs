//! `ridge-id identify … --control`: the flow controller for the identified model, designed
//! with the same ridge-core code the firmware runs ([`ridge_core::control`], here in `f64`),
//! its closed-loop poles, and a simulated setpoint step for the plot.
//!
//! # Conventions
//! Polynomials in the backward shift `q⁻¹`, coefficient lists in ascending powers
//! (`a[k]` multiplies `q⁻ᵏ`).
//! - Model: `A(q⁻¹) y_t = q^{−d} B(q⁻¹) u_t + c`, `A = [1, −θ₁, …, −θ_p]`,
//!   `B = [φ₀, …, φ_{q−1}]`.
//! - Controller: `R(q⁻¹) u_{t+1} = T(q⁻¹) r_{t+1} − S(q⁻¹) y_t`, `R` monic: the input for the
//!   next sample interval from the readings up to `y_t`.
//! - Closed loop: `P = A R + q^{−d−1} B S`; its poles are the roots `z` of
//!   `P₀ zⁿ + P₁ zⁿ⁻¹ + … + Pₙ` (inside the unit circle: stable). Integral action:
//!   `R(1) = 0`; unit static gain: `T(1) = S(1)`.
//! - Modulus margin: `1 / max_ω |A R / P|` on the unit circle (the smallest distance of the
//!   loop transfer to −1; at least 0.5 is required).
//!
//! # What is checked, in this order
//! 1. The model ([`check_model`]): finite coefficients; every pole of `A` within
//!    [`STABLE_RADIUS`] (the firmware's); static gain `B(1)/A(1)` positive (more input, more
//!    output), or within `--gain-min..=--gain-max` when given (the firmware accepts 20..2000
//!    slm per unit duty: pass `--gain-min 20 --gain-max 2000` for a pump log in those units;
//!    there is no absolute default, the log's units being unknown here). A unit-free size
//!    check too: over the log's `u` span the gain must move `y` by at least [`MIN_EFFECT`]
//!    (1 %) of the log's `y` span (this refuses a model with `B(1) ≈ 0`).
//! 2. The design ([`design_slower_on_failure`], as the firmware calls it: [`TRIES`] designs,
//!    each [`SLOWDOWN`] times slower than the last while the closed-loop pole check or the
//!    modulus-margin check fails): the closed loop built equals the designed `P`, its roots
//!    lie within the slowest designed pole + 0.01, the modulus margin is at least 0.5.
//!
//! A refusal is a [`Refusal`] (which check, with its numbers), not an error: the
//! identification is still reported, and the binary exits with [`EXIT_REFUSED`].

use nalgebra::{DMatrix, Schur};
use ridge_core::control::{
    check_model, design_slower_on_failure, exp_neg, Controller, Design, DesignError, Limits,
    ModelFault, ModelLimits, Spec, REFERENCE_S,
};
use ridge_core::ArxModel;

use crate::error::IdError;

/// Designs made before the controller is refused: the firmware's default
/// (`ControlConfig::DEFAULT.tries` in `firmware/src/selfid/config.rs`; ridge-core has no
/// constant for it).
pub const TRIES: u8 = 5;

/// Each retry of a refused design is this many times slower (`τ` and the observer pole): the
/// firmware's `selfid::SLOWDOWN` (`firmware/src/selfid/design.rs`; ridge-core has no constant
/// for it).
pub const SLOWDOWN: f64 = 1.5;

/// Every model pole must lie within this radius: the firmware's default
/// (`ControlConfig::DEFAULT.model.stable_radius`).
pub const STABLE_RADIUS: f64 = 0.995;

/// Default sample period, s: the pump's 100 Hz. (The CSV's `t` column is not read.)
pub const DEFAULT_TS: f64 = 0.01;

/// Exit status of `ridge-id` when the controller is refused (the report is still printed).
pub const EXIT_REFUSED: u8 = 3;

/// Smallest steady-state effect of the input over the log's `u` span, `|gain| · Δu`, as a
/// fraction of the log's `y` span `Δy` (a unit-free size check of the static gain).
pub const MIN_EFFECT: f64 = 0.01;

/// Trailing coefficients of `P` below this fraction of its largest term are roundoff of
/// poles placed at 0, and are reported as poles at exactly 0.
const ZERO_POLE_TOLERANCE: f64 = 1e-10;

/// What `--control` does: the design's settings, the model checks and the step simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOptions {
    /// Sample period of the log, s (default [`DEFAULT_TS`]).
    pub ts: f64,
    /// The speed knob, [`Spec::tau`]: time constant of the setpoint response, s. `None`: a
    /// quarter of the model's open-loop time constant (from its slow pole), between `2 Ts`
    /// and 2 s; 0.1 s for a model without a slow pole (ridge-core's rule).
    pub speed: Option<f64>,
    /// Time constant of the observer pole, [`Spec::observer`], s (default ridge-core's and
    /// the firmware's 0.095 s: `β = 0.9` at 100 Hz). It buys robustness: the slower, the larger
    /// the modulus margin, at the price of a slower disturbance rejection. At another sample
    /// period scale it with `Ts` (e.g. `9.5 Ts` keeps `β = 0.9`).
    pub observer: f64,
    /// Smallest accepted static gain, output units per input unit (`None`: any positive
    /// gain).
    pub gain_min: Option<f64>,
    /// Largest accepted static gain (`None`: no limit).
    pub gain_max: Option<f64>,
    /// Smallest input of the simulated loop (`None`: the smallest `u` of the log).
    pub u_min: Option<f64>,
    /// Largest input of the simulated loop (`None`: the largest `u` of the log).
    pub u_max: Option<f64>,
    /// Largest input change per sample of the simulated loop (`None`: no rate limit).
    pub u_step: Option<f64>,
}

impl Default for ControlOptions {
    fn default() -> Self {
        ControlOptions {
            ts: DEFAULT_TS,
            speed: None,
            observer: Spec::<f64>::new(DEFAULT_TS).observer,
            gain_min: None,
            gain_max: None,
            u_min: None,
            u_max: None,
            u_step: None,
        }
    }
}

impl ControlOptions {
    /// Checks the values, with a message naming the option.
    pub fn check(&self) -> Result<(), IdError> {
        let bad = |m: String| Err(IdError::Usage(m));
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.ts) {
            return bad(format!(
                "--ts {}: must be a sample period in seconds above 0",
                self.ts
            ));
        }
        if let Some(s) = self.speed {
            if !positive(s) {
                return bad(format!(
                    "--speed {s}: must be a time constant in seconds above 0"
                ));
            }
        }
        if !positive(self.observer) {
            return bad(format!(
                "--observer {}: must be a time constant in seconds above 0",
                self.observer
            ));
        }
        for (name, v) in [
            ("--gain-min", self.gain_min),
            ("--gain-max", self.gain_max),
            ("--u-min", self.u_min),
            ("--u-max", self.u_max),
        ] {
            if let Some(v) = v {
                if !v.is_finite() {
                    return bad(format!("{name} {v}: must be a finite number"));
                }
            }
        }
        if let (Some(a), Some(b)) = (self.gain_min, self.gain_max) {
            if a > b {
                return bad(format!("--gain-min {a} is above --gain-max {b}"));
            }
        }
        if let (Some(a), Some(b)) = (self.u_min, self.u_max) {
            if a >= b {
                return bad(format!("--u-min {a} must be below --u-max {b}"));
            }
        }
        if let Some(s) = self.u_step {
            if !positive(s) {
                return bad(format!("--u-step {s}: must be a number above 0"));
            }
        }
        Ok(())
    }

    /// The model limits of these options (see the [module docs](self)).
    pub fn model_limits(&self) -> ModelLimits<f64> {
        ModelLimits {
            stable_radius: STABLE_RADIUS,
            gain_min: self.gain_min.unwrap_or(f64::MIN_POSITIVE),
            gain_max: self.gain_max.unwrap_or(f64::INFINITY),
        }
    }

    /// The design settings: ridge-core's defaults at [`ControlOptions::ts`] with the speed
    /// knob and the observer, as the firmware builds them.
    pub fn spec(&self) -> Spec<f64> {
        Spec {
            tau: self.speed,
            observer: self.observer,
            ..Spec::new(self.ts)
        }
    }

    /// The input limits of the simulated loop: these options, else the log's input range
    /// `u_range`; no rate limit unless [`ControlOptions::u_step`].
    pub fn limits(&self, u_range: (f64, f64)) -> Result<Limits<f64>, IdError> {
        let min = self.u_min.unwrap_or(u_range.0);
        let max = self.u_max.unwrap_or(u_range.1);
        if min.is_nan() || max.is_nan() || min >= max {
            return Err(IdError::Usage(format!(
                "the simulated loop's input limits are empty: u from {min} to {max} \
                 (the log's u range is {} to {}; set --u-min and --u-max)",
                u_range.0, u_range.1
            )));
        }
        Ok(Limits {
            min,
            max,
            max_step: self.u_step.unwrap_or(f64::INFINITY),
        })
    }
}

/// A pole (or any complex number) `re + j im`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pole {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl Pole {
    /// `|z|`.
    pub fn norm(self) -> f64 {
        self.re.hypot(self.im)
    }
}

/// The roots `z` of the polynomial `a` in `q⁻¹` (ascending powers, `a[0] ≠ 0`): the
/// eigenvalues of the companion matrix of `zⁿ + (a₁/a₀) zⁿ⁻¹ + … + aₙ/a₀` (nalgebra's real
/// Schur decomposition). Trailing coefficients of magnitude at most `zero_below` count as 0
/// (roots at exactly 0). Sorted by decreasing `|z|`, then decreasing imaginary part. `None`
/// for non-finite coefficients, `a[0] = 0`, or no convergence.
pub fn roots(a: &[f64], zero_below: f64) -> Option<Vec<Pole>> {
    let lead = *a.first()?;
    if lead == 0.0 || !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut n = a.len();
    while n > 1 && a[n - 1].abs() <= zero_below {
        n -= 1;
    }
    let zeros = a.len() - n;
    let deg = n - 1;
    let mut out = Vec::with_capacity(a.len() - 1);
    if deg > 0 {
        // Companion matrix: first row −a₁/a₀ … −aₙ/a₀, ones below the diagonal.
        let m = DMatrix::from_fn(deg, deg, |i, j| {
            if i == 0 {
                -a[j + 1] / lead
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let schur = Schur::try_new(m, f64::EPSILON, 10_000)?;
        for z in schur.complex_eigenvalues().iter() {
            if !(z.re.is_finite() && z.im.is_finite()) {
                return None;
            }
            out.push(Pole { re: z.re, im: z.im });
        }
    }
    out.extend(std::iter::repeat_n(Pole { re: 0.0, im: 0.0 }, zeros));
    out.sort_by(|x, y| {
        y.norm()
            .total_cmp(&x.norm())
            .then(y.im.total_cmp(&x.im))
            .then(y.re.total_cmp(&x.re))
    });
    Some(out)
}

/// `A = [1, −θ₁, …, −θ_p]` of a model with autoregressive coefficients `theta`.
pub fn denominator(theta: &[f64]) -> Vec<f64> {
    std::iter::once(1.0)
        .chain(theta.iter().map(|t| -t))
        .collect()
}

/// `a · b` (polynomial product, ascending powers), every coefficient kept: ridge-core's
/// [`poly::mul`](ridge_core::control::poly::mul) into a vector of the product's length.
pub fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; (a.len() + b.len()).saturating_sub(1)];
    ridge_core::control::poly::mul(a, b, &mut out);
    out
}

/// The closed-loop polynomial `P = A R + q^{−d−1} B S` of `model` with the controller `r`,
/// `s`, and the size of its largest term (for the zero-pole tolerance).
pub fn closed_loop(model: &ArxModel<f64>, r: &[f64], s: &[f64]) -> (Vec<f64>, f64) {
    let ar = mul(&denominator(model.theta()), r);
    let d = usize::from(model.structure().d);
    let mut b1 = vec![0.0; d + 1];
    b1.extend_from_slice(model.phi());
    let bs = mul(&b1, s);
    let mut p = vec![0.0; ar.len().max(bs.len())];
    let mut scale = 0.0f64;
    for (k, v) in ar.iter().enumerate() {
        p[k] += v;
        scale = scale.max(v.abs());
    }
    for (k, v) in bs.iter().enumerate() {
        p[k] += v;
        scale = scale.max(v.abs());
    }
    (p, scale)
}

/// `design`'s controller in the conventions `R u_{t+1} = T r_{t+1} − S y_t` (ascending powers
/// of `q⁻¹`, `R` monic): `(R, S, T)`. Without a reference model these are ridge-core's `R`,
/// `S`, `T = t₀ A_o`. With one ([`Design::set_reference`]) the controller runs
/// `R u = t₀ A_o r' − S y` on the shaped setpoint
/// `r' = (1 − γ)(1 − α q⁻¹) / ((1 − α)(1 − γ q⁻¹)) r`; multiplied by `1 − γ q⁻¹` that is
/// `R (1 − γ q⁻¹) u = t₀ (1 − γ)/(1 − α) A_o (1 − α q⁻¹) r − S (1 − γ q⁻¹) y`, the same
/// controller in the conventions (integral action and `T(1) = S(1)` kept).
pub fn conventions(design: &Design<f64>) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let rst = &design.rst;
    let t = rst.t().to_vec();
    match rst.reference_pole() {
        Some(gamma) => {
            let shift = [1.0, -gamma];
            let gain = (1.0 - gamma) / (1.0 - design.alpha);
            let t: Vec<f64> = t.iter().map(|x| x * gain).collect();
            (
                mul(rst.r(), &shift),
                mul(rst.s(), &shift),
                mul(&t, &[1.0, -design.alpha]),
            )
        }
        None => (rst.r().to_vec(), rst.s().to_vec(), t),
    }
}

/// A controller that passed every check.
#[derive(Debug, Clone, PartialEq)]
pub struct Designed {
    /// ridge-core's design: `R`, `S`, `T` (and the anti-windup `A_o`), `τ` (s), `α`, `β`,
    /// model poles kept, modulus margin, and the settings of the design that passed.
    pub design: Design<f64>,
    /// Designs made (1 when the first passed).
    pub tries: u8,
    /// `τ` was derived from the model (no `--speed`).
    pub tau_derived: bool,
    /// [`Design::mean_delay`]: mean delay of the designed setpoint response, samples.
    pub mean_delay: f64,
    /// The time constant of the setpoint's reference model, s ([`REFERENCE_S`] without
    /// `--speed`, as the firmware), `None` without one.
    pub reference_s: Option<f64>,
    /// The controller in the conventions `R u_{t+1} = T r_{t+1} − S y_t`, the reference model
    /// included ([`conventions`]): `R`, `S`, `T`, ascending powers of `q⁻¹`.
    pub r: Vec<f64>,
    /// See [`Designed::r`].
    pub s: Vec<f64>,
    /// See [`Designed::r`].
    pub t: Vec<f64>,
    /// `P = A R + q^{−d−1} B S` of [`Designed::r`] and [`Designed::s`], ascending powers of
    /// `q⁻¹` (with a reference model its pole `γ` is a root: a pole of the setpoint
    /// response).
    pub closed_loop: Vec<f64>,
    /// The roots of `P` (see [`roots`]); empty if they could not be computed.
    pub poles: Vec<Pole>,
}

/// Which check refused the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// A model coefficient is not finite.
    NonFinite,
    /// A model pole lies outside [`STABLE_RADIUS`].
    Unstable,
    /// The static gain is not positive, or outside `--gain-min..=--gain-max`.
    Gain,
    /// The design settings are not positive and finite.
    Spec,
    /// The model cannot be controlled (`B` shares a root with `A (1 − q⁻¹)`).
    Singular,
    /// More than one slow model pole, or a slow complex pair.
    SlowPoles,
    /// The closed loop is not the designed one, or its roots are too slow.
    Poles,
    /// The modulus margin is below 0.5.
    Margin,
}

impl Check {
    /// The name in the JSON's `"check"`: `non-finite`, `unstable`, `gain`, `spec`,
    /// `singular`, `slow-poles`, `poles`, `margin`.
    pub fn name(self) -> &'static str {
        match self {
            Check::NonFinite => "non-finite",
            Check::Unstable => "unstable",
            Check::Gain => "gain",
            Check::Spec => "spec",
            Check::Singular => "singular",
            Check::SlowPoles => "slow-poles",
            Check::Poles => "poles",
            Check::Margin => "margin",
        }
    }
}

/// Why no controller was designed.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// The check that failed.
    pub check: Check,
    /// One line: the check, with its numbers.
    pub reason: String,
    /// Designs made (0 when the model check failed).
    pub tries: u8,
}

/// The result of `--control`.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlReport {
    /// The options it ran with.
    pub options: ControlOptions,
    /// The model limits checked.
    pub limits: ModelLimits<f64>,
    /// The model's poles, roots of `A` (see [`roots`]).
    pub model_poles: Vec<Pole>,
    /// The model's static gain `B(1)/A(1)`, output units per input unit.
    pub gain: f64,
    /// The spans of the log (for the gain's size check).
    pub span: LogSpan,
    /// The controller, or why there is none.
    pub outcome: Result<Designed, Refusal>,
}

impl ControlReport {
    /// The designed controller, if any.
    pub fn designed(&self) -> Option<&Designed> {
        self.outcome.as_ref().ok()
    }

    /// The refusal, if any.
    pub fn refusal(&self) -> Option<&Refusal> {
        self.outcome.as_ref().err()
    }
}

/// `0.950000, 0.4 ± 0.3i`: poles for a message.
pub fn pole_list(poles: &[Pole]) -> String {
    poles
        .iter()
        .map(|p| format_pole(*p))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `0.400000+0.300000i (|z| 0.500000)` or `0.950000` for a real pole.
pub fn format_pole(p: Pole) -> String {
    if p.im == 0.0 {
        format!("{:.6}", p.re)
    } else {
        format!(
            "{:.6}{}{:.6}i (|z| {:.6})",
            p.re,
            if p.im < 0.0 { "-" } else { "+" },
            p.im.abs(),
            p.norm()
        )
    }
}

/// The spans of the log the model was identified on: `max − min` of its `u` and `y` columns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogSpan {
    /// Input span, input units.
    pub u: f64,
    /// Output span, output units.
    pub y: f64,
}

/// The identified model (ridge-core-host, the host's maxima) as ridge-core's model, the one
/// the firmware's controller design takes.
///
/// Errors: a structure beyond the device's maxima (`p`, `q`, `d` ≤ 6), as a usage error
/// naming the structure.
pub fn device_model(model: &ridge_core_host::ArxModel<f64>) -> Result<ArxModel<f64>, IdError> {
    let s = model.structure();
    let offset = match model.offset() {
        ridge_core_host::Offset::None => ridge_core::Offset::None,
        ridge_core_host::Offset::Intercept => ridge_core::Offset::Intercept,
    };
    ArxModel::new(model.theta(), model.phi(), s.d, offset, model.intercept()).map_err(|e| {
        IdError::Usage(format!(
            "--control: the identified structure (p = {}, q = {}, d = {}) is beyond the \
             firmware's controller design (p, q, d ≤ {}, {}, {}): narrow --p, --q, --d ({e})",
            s.p,
            s.q,
            s.d,
            ridge_core::P_MAX,
            ridge_core::Q_MAX,
            ridge_core::D_MAX
        ))
    })
}

/// Checks `model` (identified on a log of spans `span`) and designs its controller as the
/// firmware does (see the [module docs](self)). Never panics; a refusal is in
/// [`ControlReport::outcome`].
pub fn control(model: &ArxModel<f64>, opts: &ControlOptions, span: LogSpan) -> ControlReport {
    let limits = opts.model_limits();
    let model_poles = roots(&denominator(model.theta()), 0.0).unwrap_or_default();
    let gain = model.static_gain();
    let outcome = check_and_design(model, opts, &limits, &model_poles, span);
    ControlReport {
        options: *opts,
        limits,
        model_poles,
        gain,
        span,
        outcome,
    }
}

fn check_and_design(
    model: &ArxModel<f64>,
    opts: &ControlOptions,
    limits: &ModelLimits<f64>,
    model_poles: &[Pole],
    span: LogSpan,
) -> Result<Designed, Refusal> {
    let refuse = |check: Check, tries: u8, reason: String| Refusal {
        check,
        reason,
        tries,
    };
    let effect = |gain: f64| gain.abs() * span.u;
    if let Err(fault) = check_model(model, limits) {
        return Err(match fault {
            ModelFault::NonFinite => refuse(
                Check::NonFinite,
                0,
                "model check: a coefficient of the model is not finite".into(),
            ),
            ModelFault::Unstable => {
                let outside: Vec<Pole> = model_poles
                    .iter()
                    .copied()
                    .filter(|p| p.norm() >= limits.stable_radius)
                    .collect();
                let largest = model_poles.first().map_or(f64::NAN, |p| p.norm());
                refuse(
                    Check::Unstable,
                    0,
                    format!(
                        "model check: unstable: pole(s) {} outside the radius {} (largest |z| = {:.6}); \
                         a controller is designed only for a stable model",
                        pole_list(&outside),
                        limits.stable_radius,
                        largest
                    ),
                )
            }
            ModelFault::Gain { gain } => {
                let range = match (opts.gain_min, opts.gain_max) {
                    (None, None) => "above 0 (more input, more output)".to_string(),
                    (None, Some(b)) => format!("above 0 and at most {b} (--gain-max)"),
                    (Some(a), None) => format!("at least {a} (--gain-min)"),
                    (Some(a), Some(b)) => format!("in {a}..={b} (--gain-min, --gain-max)"),
                };
                let why = if gain.is_infinite() {
                    " (an integrating model: A(1) = 0)"
                } else if gain == 0.0 {
                    " (B(1) = 0: no steady-state effect of the input)"
                } else if gain < 0.0 && opts.gain_min.is_none() {
                    " (the wrong sign: more input, less output)"
                } else {
                    ""
                };
                refuse(
                    Check::Gain,
                    0,
                    format!("model check: static gain B(1)/A(1) = {gain:.6}{why} must be {range}"),
                )
            }
        });
    }
    let gain = model.static_gain();
    if effect(gain).is_nan() || effect(gain) < MIN_EFFECT * span.y {
        return Err(refuse(
            Check::Gain,
            0,
            format!(
                "model check: static gain B(1)/A(1) = {gain:.6e} too small for the log: over its u \
                 span {:.6} it moves y by {:.6e} at steady state, under {} % of the log's y span \
                 {:.6} (the input has next to no steady-state effect{})",
                span.u,
                effect(gain),
                MIN_EFFECT * 100.0,
                span.y,
                if model.phi().iter().sum::<f64>() == 0.0 {
                    ": B(1) = 0"
                } else {
                    ""
                }
            ),
        ));
    }
    let spec = opts.spec();
    let (result, tries) = design_slower_on_failure(model, &spec, TRIES, SLOWDOWN, || {});
    let slowed = SLOWDOWN.powi(i32::from(tries) - 1);
    match result {
        Ok(mut design) => {
            // As the firmware: without a speed given, the setpoint response is the
            // reference model's. γ = e^{−Ts/0.08} is in 0..1 for the Ts the design accepted.
            let reference_s = opts.speed.is_none().then_some(REFERENCE_S);
            if let Some(tau_ref) = reference_s {
                if design.set_reference(exp_neg(spec.ts / tau_ref)).is_err() {
                    return Err(refuse(
                        Check::Spec,
                        tries,
                        format!("design: reference model {tau_ref} s at Ts = {} s", spec.ts),
                    ));
                }
            }
            let (r, s, t) = conventions(&design);
            let (closed, scale) = closed_loop(model, &r, &s);
            let poles = roots(&closed, ZERO_POLE_TOLERANCE * scale).unwrap_or_default();
            Ok(Designed {
                design,
                tries,
                tau_derived: opts.speed.is_none(),
                mean_delay: design.mean_delay(model),
                reference_s,
                r,
                s,
                t,
                closed_loop: closed,
                poles,
            })
        }
        Err(e) => Err(match e {
            DesignError::Spec => refuse(
                Check::Spec,
                tries,
                format!(
                    "design: settings not positive and finite (Ts = {} s, tau = {}, observer {} s)",
                    spec.ts,
                    spec.tau
                        .map_or("derived from the model".to_string(), |t| format!("{t} s")),
                    spec.observer
                ),
            ),
            DesignError::Singular => refuse(
                Check::Singular,
                tries,
                format!(
                    "design: singular: B shares a root with A (1 - q^-1) (B(1) = {:.6}, model poles {}): \
                     the model cannot be controlled",
                    model.phi().iter().sum::<f64>(),
                    pole_list(model_poles)
                ),
            ),
            DesignError::SlowPoles => {
                let slow: Vec<Pole> = model_poles
                    .iter()
                    .copied()
                    .filter(|p| p.norm() >= spec.keep_radius)
                    .collect();
                refuse(
                    Check::SlowPoles,
                    tries,
                    format!(
                        "design: slow model poles {} (|z| at least the keep radius {}): this design \
                         moves one real slow pole (a blower's lag) and keeps the others, so it needs \
                         at most one pole outside {} and a real one (a smaller structure, --p or \
                         --structure, may have a single slow pole)",
                        pole_list(&slow),
                        spec.keep_radius,
                        spec.keep_radius
                    ),
                )
            }
            DesignError::Poles => refuse(
                Check::Poles,
                tries,
                format!(
                    "design: after {tries} designs (the last {slowed:.3} times slower than the first) \
                     the closed loop A R + q^-(d+1) B S is not the designed P to 1e-3, or a root lies \
                     beyond the slowest designed pole + 0.01"
                ),
            ),
            DesignError::Margin { margin } => refuse(
                Check::Margin,
                tries,
                format!(
                    "design: modulus margin {margin:.4} below {} after {tries} designs (the last \
                     {slowed:.3} times slower than the first; a larger --speed or --observer buys \
                     margin)",
                    spec.min_margin
                ),
            ),
        }),
    }
}

/// A simulated closed-loop setpoint response (for the plot): sample `k` at `k · ts` s.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// Sample period, s.
    pub ts: f64,
    /// Setpoint `r_k` (output units).
    pub r: Vec<f64>,
    /// Output `y_k` of the simulated plant (output units).
    pub y: Vec<f64>,
    /// Input `u_k` applied during the interval that ends with `y_k` (input units).
    pub u: Vec<f64>,
    /// The controller's input limits.
    pub limits: Limits<f64>,
}

/// Simulates the designed controller ([`Controller`], with `limits`) on `model` itself as
/// the plant (intercept included, no noise): from the steady state at the middle of the input
/// range, the setpoint steps to the steady output of the input at 70 % of
/// the range, and back. Each step is held for `10 τ` plus `2 (d + q) + 10` samples (at least
/// 40, at most 3000), after a lead of a fifth of that. `None` when the model has no finite steady state.
pub fn simulate_step(
    model: &ArxModel<f64>,
    design: &Design<f64>,
    limits: Limits<f64>,
    ts: f64,
) -> Option<StepResponse> {
    let a1: f64 = 1.0 - model.theta().iter().sum::<f64>();
    let b1: f64 = model.phi().iter().sum();
    let c = model.intercept();
    let steady = |u: f64| (b1 * u + c) / a1;
    let u0 = 0.5 * (limits.min + limits.max);
    let u1 = limits.min + 0.7 * (limits.max - limits.min);
    let (y0, y1) = (steady(u0), steady(u1));
    if !(y0.is_finite() && y1.is_finite()) {
        return None;
    }
    let s = model.structure();
    let (p, q, d) = (usize::from(s.p), usize::from(s.q), usize::from(s.d));
    // Long enough for the slower of the regulation loop and the setpoint response (the
    // reference model's time constant, `−Ts / ln γ`).
    let tau = design.tau.max(-ts / design.gamma.ln());
    let hold = (10.0 * tau / ts).ceil() + (2 * (d + q) + 10) as f64;
    let hold = if hold.is_finite() {
        hold.clamp(40.0, 3000.0) as usize
    } else {
        3000
    };
    let lead = (hold / 5).max(5);
    let n = lead + 2 * hold;
    let r: Vec<f64> = (0..=n)
        .map(|k| {
            if (lead..lead + hold).contains(&k) {
                y1
            } else {
                y0
            }
        })
        .collect();
    // Histories before sample 0 at the operating point; index `pad + k` is sample k.
    let pad = p.max(d + q);
    let mut u = vec![u0; pad + n + 1];
    let mut y = vec![y0; pad + n + 1];
    let mut ctrl = Controller::new(design.rst, limits);
    ctrl.start(u0, y0);
    for k in 0..n {
        let t = pad + k + 1;
        u[t] = ctrl.step(r[k + 1], y[t - 1]);
        let mut v = c;
        for (i, th) in model.theta().iter().enumerate() {
            v += th * y[t - 1 - i];
        }
        for (j, ph) in model.phi().iter().enumerate() {
            v += ph * u[t - d - j];
        }
        y[t] = v;
    }
    Some(StepResponse {
        ts,
        r,
        y: y.split_off(pad),
        u: u.split_off(pad),
        limits,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ridge_core::Offset;

    #[test]
    fn roots_of_known_polynomials() {
        // (1 − 0.5 q⁻¹)(1 − 0.25 q⁻¹) q⁻⁰ with a trailing exact zero: roots 0.5, 0.25, 0.
        let r = roots(&[1.0, -0.75, 0.125, 0.0], 1e-12).unwrap();
        let want = [0.5, 0.25, 0.0];
        assert_eq!(r.len(), 3);
        for (p, w) in r.iter().zip(want) {
            assert!((p.re - w).abs() < 1e-12 && p.im == 0.0, "{r:?}");
        }
        // 1 − q⁻¹ + 0.5 q⁻²: 0.5 ± 0.5i, the positive imaginary part first.
        let r = roots(&[1.0, -1.0, 0.5], 0.0).unwrap();
        assert!((r[0].re - 0.5).abs() < 1e-12 && (r[0].im - 0.5).abs() < 1e-12);
        assert!((r[1].im + 0.5).abs() < 1e-12);
        assert!(roots(&[0.0, 1.0], 0.0).is_none());
        assert!(roots(&[1.0, f64::NAN], 0.0).is_none());
        assert_eq!(roots(&[2.0], 0.0), Some(vec![]));
    }

    #[test]
    fn products_of_known_factors() {
        // (1 − 0.5 q⁻¹)(1 − 0.25 q⁻¹) = 1 − 0.75 q⁻¹ + 0.125 q⁻².
        assert_eq!(mul(&[1.0, -0.5], &[1.0, -0.25]), vec![1.0, -0.75, 0.125]);
        // (1 + q⁻¹)³ = 1 + 3 q⁻¹ + 3 q⁻² + q⁻³, every coefficient kept.
        assert_eq!(
            mul(&mul(&[1.0, 1.0], &[1.0, 1.0]), &[1.0, 1.0]),
            vec![1.0, 3.0, 3.0, 1.0]
        );
        assert_eq!(mul(&[2.0], &[0.0, 0.0, 3.0]), vec![0.0, 0.0, 6.0]);
        assert!(mul(&[], &[]).is_empty());
        assert_eq!(mul(&[], &[1.0, 2.0]), vec![0.0]);
    }

    fn model(theta: &[f64], phi: &[f64], d: u8) -> ArxModel<f64> {
        ArxModel::new(theta, phi, d, Offset::None, 0.0).unwrap()
    }

    const SPAN: LogSpan = LogSpan { u: 1.0, y: 1.0 };

    fn control(m: &ArxModel<f64>, o: &ControlOptions) -> ControlReport {
        super::control(m, o, SPAN)
    }

    #[test]
    fn refusals_name_the_check() {
        let o = ControlOptions::default();
        let r = control(&model(&[1.02], &[1.0], 0), &o);
        assert_eq!(r.refusal().unwrap().check, Check::Unstable);
        let r = control(&model(&[0.9], &[-1.0], 0), &o);
        let f = r.refusal().unwrap();
        assert_eq!(f.check, Check::Gain);
        assert!(f.reason.contains("-10.0"), "{}", f.reason);
        // B(1) = 0.
        let r = control(&model(&[0.9], &[1.0, -1.0], 0), &o);
        assert_eq!(r.refusal().unwrap().check, Check::Gain);
        // Let a zero gain through the model checks (sign and size): the design is singular,
        // no panic.
        let z = ControlOptions {
            gain_min: Some(-1.0),
            ..o
        };
        let flat = LogSpan { u: 1.0, y: 0.0 };
        let r = super::control(&model(&[0.9], &[1.0, -1.0], 0), &z, flat);
        assert_eq!(r.refusal().unwrap().check, Check::Singular, "{r:?}");
        // A tiny gain for the log's spans.
        let r = super::control(&model(&[0.9], &[1e-5], 0), &o, SPAN);
        let f = r.refusal().unwrap();
        assert_eq!(f.check, Check::Gain);
        assert!(f.reason.contains("too small"), "{}", f.reason);
        // A slow complex pair.
        let r = control(&model(&[1.5, -0.7], &[1.0, 0.5], 2), &o);
        assert_eq!(r.refusal().unwrap().check, Check::SlowPoles);
    }

    #[test]
    fn design_of_a_blower_like_model() {
        let m = model(&[1.35, -0.38], &[0.5, 0.3], 2);
        let r = control(&m, &ControlOptions::default());
        let c = r.designed().expect("designed");
        assert_eq!(c.tries, 1);
        assert_eq!(c.design.kept, 1);
        assert!(c.poles.iter().all(|p| p.norm() < 1.0));
        let limits = Limits {
            min: -1.0,
            max: 1.0,
            max_step: f64::INFINITY,
        };
        let s = simulate_step(&m, &c.design, limits, 0.01).unwrap();
        assert_eq!(s.r.len(), s.y.len());
        // Settled on the setpoint at the end of the first hold and of the run.
        let k = s.r.iter().rposition(|&v| v != s.r[0]).unwrap();
        assert!(
            (s.y[k] - s.r[k]).abs() < 1e-3 * s.r[k].abs(),
            "{k} {:?}",
            s.y
        );
        let last = s.y.len() - 1;
        assert!((s.y[last] - s.r[last]).abs() < 1e-3);
    }
}
