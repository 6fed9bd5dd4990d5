//! The firmware's controller with its three time constants chosen per plant, in hindsight:
//! how far the pole-placement design of `ridge_core::control` goes on each plant when its
//! knobs are tuned on the simulator itself, with the plant, the setpoints and the noise known.
//!
//! The firmware fixes the knobs from the identified model ([`ControlConfig`]: the regulation
//! loop's `τ` a quarter of the model's open-loop time constant, the observer pole's
//! `τ_o` = 0.095 s, the setpoint's reference model 0.08 s). Here each is varied around the
//! firmware's own design ([`Knobs`]) and the resulting controller is run from the firmware's
//! switch-over on the same rig, noise and program as the comparison
//! ([`super::experiment`]), then scored as there. What this measures is a bound for the
//! method, not a controller that could run: the choice uses the true plant.
//!
//! The loop here is `ridge_core::control::Controller` itself, fed as the firmware's run mode
//! feeds it (the reading in slm, the program `preview` ticks ahead, its output a flow turned
//! into duty through the model's map within the duty limits and rate limit, the map's flow at
//! that duty back into its memory); with [`Knobs::FIRMWARE`] its duties equal the firmware's
//! run mode's (test `the_firmware_knobs_reproduce_the_firmwares_run` in
//! `pump-sim/tests/baseline.rs`).

use ridge_core::control::{design_slower_on_failure, Controller, Design, Limits};
use ridge_pump_firmware::selfid::{
    duty_for_flow, preview_ticks, ControlConfig, REFERENCE_POLE, SLOWDOWN,
};
use ridge_pump_firmware::setpoint;
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, SLM_PER_COUNT};

use super::experiment::{
    firmware_design, noise_free_sensor, run_loop, score, Scores, Switchover, Trace,
};
use crate::{Rig, Sfm3300, TS_S};

/// The three time constants of a design, relative to the firmware's own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knobs {
    /// Factor on the regulation loop's `τ` of the firmware's design (after its retries).
    pub tau_x: f32,
    /// Factor on the observer pole's time constant of the firmware's design (0.095 s, times
    /// 1.5 per retry).
    pub observer_x: f32,
    /// The setpoint's reference-model pole `γ = e^{−Ts/τ_ref}`; `None`: no reference model
    /// (the setpoint response has the regulation loop's `τ`).
    pub reference: Option<f32>,
}

impl Knobs {
    /// The firmware's design: its `τ`, its observer, its 0.08 s reference model.
    pub const FIRMWARE: Knobs = Knobs {
        tau_x: 1.0,
        observer_x: 1.0,
        reference: Some(REFERENCE_POLE),
    };

    /// The reference model's time constant, s (`None` without one).
    pub fn reference_s(&self) -> Option<f64> {
        self.reference.map(|g| -TS_S / f64::from(g).ln())
    }

    /// The pole of a reference model with time constant `s` seconds at the firmware's rate.
    pub fn pole(s: f64) -> f32 {
        (-TS_S / s).exp() as f32
    }
}

/// The firmware's design for `sw`'s model with `knobs` applied: the firmware's settings `c`
/// and retries give `τ` and `τ_o`, which are then scaled and designed again (slower on a
/// refusal, as the firmware retries); `None` when refused.
pub fn design_with(sw: &Switchover, c: &ControlConfig, knobs: Knobs) -> Option<Design<f32>> {
    let model = &sw.model;
    let base = firmware_design(model, c)?;
    // Unscaled knobs keep the firmware's design itself (its spec and retries as they were),
    // not a redesign from its resolved time constants.
    let mut d = if knobs.tau_x == 1.0 && knobs.observer_x == 1.0 {
        base
    } else {
        let mut spec = base.spec;
        spec.tau = Some(base.tau * knobs.tau_x);
        spec.observer = spec.observer * spec.slowdown * knobs.observer_x;
        spec.slowdown = 1.0;
        design_slower_on_failure(model, &spec, c.tries, SLOWDOWN, || {})
            .0
            .ok()?
    };
    if let Some(gamma) = knobs.reference {
        d.set_reference(gamma).ok()?;
    }
    Some(d)
}

/// `ridge_core`'s controller with `design` from the switch-over `sw` on `rig` for the
/// experiment's run ([`run_loop`]), given the settings' program `preview` ticks ahead (the
/// design's mean delay, as the firmware); returns the trace and the preview.
pub fn run_design(
    rig: &mut Rig,
    sw: &Switchover,
    c: &ControlConfig,
    design: &Design<f32>,
) -> Option<(Trace, u8)> {
    let program = c.program;
    let preview = preview_ticks(design.mean_delay(&sw.model));
    // The firmware's own duty limits, through the map for the controller's; the start, the
    // reading, the inverse and the map's flow convert as its run mode does
    // (`firmware/src/selfid/run.rs`).
    let table = sw.map.table();
    let slm = |duty: u16| f32::from(table.at(duty)) * SLM_PER_COUNT;
    let duty_max = c.duty_max.min(DUTY_FULL_SCALE);
    let limits = Limits {
        min: slm(c.duty_min),
        max: slm(duty_max),
        max_step: f32::MAX,
    };
    let mut ctrl = Controller::new(design.rst, limits);
    ctrl.start(slm(sw.duty), sw.flow);
    let mut applied = sw.duty;
    let trace = run_loop(rig, sw, program, |k, raw| {
        let ahead = setpoint::value(program, sw.flow, k.saturating_add(u32::from(preview)));
        // The firmware's conversion: the sensor word to counts, counts to slm in f32.
        let y = f32::from(raw_to_counts(raw)) * SLM_PER_COUNT;
        let v = ctrl.output(ahead, y);
        let duty = duty_for_flow(&table, v, applied, c.duty_min, duty_max, c.duty_step);
        ctrl.commit(slm(duty));
        applied = duty;
        Ok(duty)
    })
    .ok()?;
    Some((trace, preview))
}

/// The scores of one design on one case: with the sensor's noise and with the noise-free
/// sensor (seed `seed`), each on the windows of the design's own preview.
pub fn score_design(
    rig: &Rig,
    sw: &Switchover,
    c: &ControlConfig,
    design: &Design<f32>,
    seed: u64,
) -> Option<(Scores, Scores)> {
    let (noisy, preview) = run_design(&mut rig.clone(), sw, c, design)?;
    let mut quiet = rig.clone();
    quiet.sensor = Sfm3300::new(noise_free_sensor(), seed);
    let (clean, _) = run_design(&mut quiet, sw, c, design)?;
    let p = u32::from(preview);
    Some((score(&noisy, false, p)?, score(&clean, false, p)?))
}

/// What a set of knobs did on one plant over its seeds. Flows in slm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KnobScore {
    /// The knobs.
    pub knobs: Knobs,
    /// Mean step IAE with the sensor's noise (true flow), slm·s.
    pub iae: f64,
    /// Largest step overshoot, noise-free, percent of the step.
    pub overshoot_pct: f64,
    /// Largest step overshoot with the sensor's noise, percent of the step.
    pub overshoot_noisy_pct: f64,
    /// Mean breath RMS tracking error with the sensor's noise, slm.
    pub breath_rms: f64,
}

/// The scores of `knobs` over the cases `(rig, switch-over, seed)` of one plant; `None` when
/// a design is refused on any of them or a trace cannot be scored.
pub fn score_knobs(
    cases: &[(Rig, Switchover, u64)],
    c: &ControlConfig,
    knobs: Knobs,
) -> Option<KnobScore> {
    let (mut iae, mut n, mut breath) = (0.0, 0usize, 0.0);
    let (mut over, mut over_noisy) = (0.0f64, 0.0f64);
    for (rig, sw, seed) in cases {
        let d = design_with(sw, c, knobs)?;
        let (noisy, clean) = score_design(rig, sw, c, &d, *seed)?;
        for m in noisy.steps.iter().flatten() {
            iae += m.iae;
            n += 1;
            over_noisy = over_noisy.max(m.overshoot_pct);
        }
        for m in clean.steps.iter().flatten() {
            over = over.max(m.overshoot_pct);
        }
        breath += noisy.breath_rms;
    }
    (n > 0).then(|| KnobScore {
        knobs,
        iae: iae / n as f64,
        overshoot_pct: over,
        overshoot_noisy_pct: over_noisy,
        breath_rms: breath / cases.len() as f64,
    })
}

/// The grid searched by `control-knobs`: `τ` × 0.5 … 3, the observer's time constant × 1 … 25
/// (0.095 … 2.4 s without retries), the reference model none or 0.02 … 0.12 s (336 sets, the
/// firmware's among them).
pub fn grid() -> Vec<Knobs> {
    let taus = [0.5, 0.75, 1.0, 1.5, 2.0, 3.0];
    let observers = [1.0, 1.5, 2.5, 4.0, 6.0, 10.0, 16.0, 25.0];
    let references = [
        None,
        Some(0.02),
        Some(0.03),
        Some(0.04),
        Some(0.06),
        Some(0.08),
        Some(0.12),
    ];
    let mut v = Vec::new();
    for &tau_x in &taus {
        for &observer_x in &observers {
            for &r in &references {
                v.push(Knobs {
                    tau_x,
                    observer_x,
                    reference: r.map(|s: f64| {
                        // The firmware's own pole for its own 0.08 s.
                        if s == ridge_core::control::REFERENCE_S {
                            REFERENCE_POLE
                        } else {
                            Knobs::pole(s)
                        }
                    }),
                });
            }
        }
    }
    v
}
