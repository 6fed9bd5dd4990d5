//! The controller of `--control` for a model, or why there is none: the model checks and the
//! design as the firmware runs them ([`control`] → [`ControlReport`]), the controller in the
//! report's conventions and its closed loop.

use ridge_core::control::{
    check_model, design_slower_on_failure, exp_neg, Design, DesignError, ModelFault, ModelLimits,
    REFERENCE_S,
};
use ridge_core::ArxModel;

use super::options::ControlOptions;
use super::poly::{denominator, mul, pole_list, roots, Pole};
use crate::error::IdError;

/// Designs made before the controller is refused: the firmware's default
/// (`ControlConfig::DEFAULT.tries` in `firmware/src/selfid/config.rs`; ridge-core has no
/// constant for it).
pub const TRIES: u8 = 5;

/// Each retry of a refused design is this many times slower (`τ` and the observer pole): the
/// firmware's `selfid::SLOWDOWN` (`firmware/src/selfid/design.rs`; ridge-core has no constant
/// for it).
pub const SLOWDOWN: f64 = 1.5;

/// Exit status of `ridge-id` when the controller is refused (the report is still printed).
pub const EXIT_REFUSED: u8 = 3;

/// Smallest steady-state effect of the input over the log's `u` span, `|gain| · Δu`, as a
/// fraction of the log's `y` span `Δy` (a unit-free size check of the static gain).
pub const MIN_EFFECT: f64 = 0.01;

/// Trailing coefficients of `P` below this fraction of its largest term are roundoff of
/// poles placed at 0, and are reported as poles at exactly 0.
const ZERO_POLE_TOLERANCE: f64 = 1e-10;

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
    /// A model pole lies outside [`STABLE_RADIUS`](super::STABLE_RADIUS).
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
/// firmware does (see the [module docs](super)). Never panics; a refusal is in
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

#[cfg(test)]
mod tests {
    use super::super::step::simulate_step;
    use super::*;
    use ridge_core::control::Limits;
    use ridge_core::Offset;

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
