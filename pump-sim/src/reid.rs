//! The closed-loop re-identification study (issue 32, item 3): the firmware identifies the
//! simulated blower and lung at power-up and designs its controller as on the device; the loop
//! then tracks square breaths while `ridge_core::reid` re-estimates the ARX part of its
//! Hammerstein model (the dynamics from the static map's flow `v` to the flow; the map stays) at
//! the same structure from the loop's own data (the direct method), checks it, and the
//! controller is re-designed and swapped at a breath boundary. The lung changes suddenly at
//! chosen breaths.
//!
//! - [`linearisation`]: the truth, the noise-free plant's small-signal step response and static
//!   gain at a steady flow (central differences of `±δ` duty steps); [`through_map`] and
//!   [`secant_through_map`]: the same as the model sees it, after the power-up's map;
//!   [`closed_valve_step`]: a volume breath's inspiration, the exhalation valve closed.
//! - [`run`]: one closed-loop run ([`Study`]) with the per-breath figures ([`BreathFigures`])
//!   and every re-estimate ([`Estimate`]).
//! - The loop's two sides, which the ventilation benchmark ([`crate::vent_bench`]) runs too:
//!   [`Running`], the firmware's controller through the static map ([`Running::tick`]: run
//!   mode's step; [`Running::swapped`]: the bumpless swap, [`Running::swapped_at`] with a given
//!   regulation speed, [`design_at`]), and [`Reestimation`], the window,
//!   the re-estimate, its hold-out and verdict, and the swap rule ([`swap_allowed`]).
//!
//! # Timing
//! As in [`crate::baseline::experiment`]: tick `k` reads the flow at the end of interval
//! `k − 1`, sets the duty of interval `k` (setpoint `value(program, start, k + preview)`), and
//! the window takes `(v_k, reading_k)` after the interval (`v_k` the map's flow at the duty
//! written), the firmware's order (statistics after the PWM write). [`Study::units`] [`Refit`]
//! units per tick. Breath `b` (from 0) is ticks `b·P … (b + 1)·P − 1`; a lung change, a
//! re-estimate's start and its verdict happen at breath boundaries, a controller swap at the
//! boundary as the controller sees it (its preview ahead).

use ridge_core::control::Limits;
use ridge_core::control::{Controller, Design};
use ridge_core::input_map::MapTable;
use ridge_core::reid::{window_len, Acceptance, Holdout, Refit, RefitStep, Rejection, Window};
use ridge_core::{ArxModel, RidgeM};
use ridge_pump_firmware::reid::ReidConfig;
use ridge_pump_firmware::selfid::{duty_for_flow, preview_ticks, REFERENCE_POLE};
use ridge_pump_firmware::setpoint::{self, BreathWave, Program, DEMO_BREATH};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, MODEL_SCALE, SLM_PER_COUNT};

use crate::baseline::experiment::{
    firmware_design, identify, ExperimentError, Switchover, EXPERIMENT_CONFIG,
};
use crate::{LungParams, PlantArgs, Rig, Sfm3300, Sfm3300Params, TS_S};

/// mL per slm·tick: `1000 mL/L / 60 s/min · TS_S`.
const ML_PER_SLM_TICK: f64 = 1000.0 / 60.0 * TS_S;

/// The small-signal behaviour of the noise-free plant at one steady flow.
#[derive(Clone, Debug, PartialEq)]
pub struct Linearisation {
    /// The steady flow, slm.
    pub flow: f64,
    /// The duty that holds it, fraction 0..1.
    pub duty: f64,
    /// Step response to a unit duty step (slm per duty fraction; through the map, slm per slm of
    /// the map's flow), tick `k` = the flow at the
    /// end of interval `k` after the step at interval 0, as `(y₊ − y₋) / 2δ`.
    pub step: Vec<f64>,
    /// The static gain, slm per duty fraction (through the map, slm per slm; the step response's
    /// last value).
    pub gain: f64,
}

/// Ticks of the truth's step responses (3 s: the slowest lung's time constant is ~0.55 s).
pub const STEP_TICKS: usize = 300;

/// The duty step of [`linearisation`], fraction (±0.5 % of full scale).
pub const DELTA: f64 = 0.005;

/// A noise-free rig with the plant's blower and `lung`, settled at `duty` (fraction).
fn settled(plant: &PlantArgs, lung: &LungParams, duty: f64) -> Rig {
    let mut rig = Rig::new(plant.pump(), Sfm3300Params::ideal(), 0).with_lung(lung.clone());
    for _ in 0..1500 {
        rig.flow_at(duty);
    }
    rig
}

/// The true linearisation of `plant`'s blower behind `lung` at the steady flow `flow` (slm):
/// the duty found by bisection on the settled flow, then `±DELTA` steps from there.
pub fn linearisation(plant: &PlantArgs, lung: &LungParams, flow: f64) -> Linearisation {
    let duty = steady_duty(plant, lung, flow);
    dithered(&settled(plant, lung, duty), flow, duty, STEP_TICKS)
}

/// The response of `base` (already set up: settled, its valve as wanted) to the duty `duty`
/// `±DELTA` for `ticks` ticks: the flow's difference over `2 DELTA` tick by tick (slm per duty
/// fraction) and its last value as the gain; `flow` (slm) is the operating point it is named by.
fn dithered(base: &Rig, flow: f64, duty: f64, ticks: usize) -> Linearisation {
    let run = |d: f64| {
        let mut rig = base.clone();
        (0..ticks).map(|_| rig.flow_at(d)).collect::<Vec<_>>()
    };
    let (up, down) = (run(duty + DELTA), run(duty - DELTA));
    let step: Vec<f64> = up
        .iter()
        .zip(&down)
        .map(|(a, b)| (a - b) / (2.0 * DELTA))
        .collect();
    let gain = step.last().copied().unwrap_or(0.0);
    Linearisation {
        flow,
        duty,
        step,
        gain,
    }
}

/// The duty (fraction) that holds the steady flow `flow` (slm) of `plant`'s blower behind
/// `lung` with the exhalation valve open, by bisection on the settled flow.
fn steady_duty(plant: &PlantArgs, lung: &LungParams, flow: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        let mut rig = settled(plant, lung, mid);
        if rig.flow_at(mid) < flow {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The small-signal response of a volume breath's inspiration, the plant the adaptive loop
/// identifies in ventilation: the noise-free blower behind `lung` settled at the steady flow
/// `from` (slm, the bias flow) with the valve open, then the valve closed and the duty stepped
/// to the one that holds `flow` (slm) with the valve open, `±DELTA`; `step` is the flow's
/// difference over `2 DELTA` tick by tick (slm per duty fraction) while the lung fills, `gain`
/// its value after `ticks` ticks (the inspiration's end). With the valve closed there is no
/// steady flow: the response rises with the blower's lag and falls as the lung's pressure
/// builds.
pub fn closed_valve_step(
    plant: &PlantArgs,
    lung: &LungParams,
    from: f64,
    flow: f64,
    ticks: usize,
) -> Linearisation {
    let mut base = settled(plant, lung, steady_duty(plant, lung, from));
    let duty = steady_duty(plant, lung, flow);
    base.valve = crate::Valve::Closed;
    dithered(&base, flow, duty, ticks)
}

/// The truth as the model sees it, through the power-up's static map `table` (duty → the map's
/// flow): `lin`'s step response and gain divided by the map's local slope at `lin`'s duty
/// (central difference over ±1 % duty), slm per slm of the map's flow.
pub fn through_map(lin: &Linearisation, table: &MapTable) -> Linearisation {
    let d = (lin.duty * f64::from(DUTY_FULL_SCALE)).round() as u16;
    let (a, b) = (
        table.at(d.saturating_sub(100)),
        table.at(d.saturating_add(100)),
    );
    // slm per duty fraction.
    let slope = f64::from(i32::from(b) - i32::from(a)) * f64::from(SLM_PER_COUNT) / 0.02;
    Linearisation {
        flow: lin.flow,
        duty: lin.duty,
        step: lin.step.iter().map(|v| v / slope).collect(),
        gain: lin.gain / slope,
    }
}

/// The secant gain of the noise-free plant between two steady flows seen through the map
/// `table`: the flows' difference over the map's flows at their duties, slm per slm.
pub fn secant_through_map(lo: &Linearisation, hi: &Linearisation, table: &MapTable) -> f64 {
    let at = |l: &Linearisation| {
        f64::from(table.at((l.duty * f64::from(DUTY_FULL_SCALE)).round() as u16))
            * f64::from(SLM_PER_COUNT)
    };
    (hi.flow - lo.flow) / (at(hi) - at(lo))
}

/// The unit step response of `model` (the map's flow → slm) over `ticks` ticks, in the same
/// convention as [`Linearisation::step`].
pub fn model_step(model: &ArxModel<f32>, ticks: usize) -> Vec<f64> {
    let theta: Vec<f64> = model.theta().iter().map(|&v| f64::from(v)).collect();
    let phi: Vec<f64> = model.phi().iter().map(|&v| f64::from(v)).collect();
    let d = usize::from(model.structure().d);
    let mut y = vec![0.0; ticks];
    for k in 0..ticks {
        let mut v = 0.0;
        for (i, th) in theta.iter().enumerate() {
            if k > i {
                v += th * y[k - 1 - i];
            }
        }
        for (j, ph) in phi.iter().enumerate() {
            if k >= d + j {
                v += ph;
            }
        }
        y[k] = v;
    }
    y
}

/// The first tick at which a step response reaches 63 % of its final value, or `None`.
pub fn rise63(step: &[f64]) -> Option<usize> {
    let last = *step.last()?;
    step.iter().position(|&v| v.abs() >= 0.632 * last.abs())
}

/// The RMS difference of two step responses over their common length, in percent of the
/// second's final value: how far an estimate's response is from the truth's.
pub fn step_error_pct(est: &[f64], truth: &[f64]) -> f64 {
    let n = est.len().min(truth.len());
    let last = truth.get(n.wrapping_sub(1)).copied().unwrap_or(1.0);
    let sse: f64 = est
        .iter()
        .zip(truth)
        .take(n)
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    100.0 * (sse / n.max(1) as f64).sqrt() / last.abs()
}

/// What the loop does with the re-estimates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// No re-estimation: the power-up controller throughout.
    Frozen,
    /// Re-estimates and judges them, never swaps (the frozen controller's loop, observed).
    Observe,
    /// Re-estimates, judges, re-designs and swaps at a breath boundary.
    Adapt,
    /// As [`Mode::Adapt`], but each swap restarts the running model's own design: the swaps'
    /// restarts without their new models (the control experiment of the adaptive runs).
    Restart,
}

/// A setpoint dither: a PRBS of `±amplitude` slm added to the controller's setpoint (its
/// preview), each bit held `hold` ticks (LFSR of order 7: period 127 bits). Its spectrum is
/// that of a random binary signal of bit time `hold · Ts`: flat to within 3 dB up to about
/// `0.44 / (hold · Ts)` Hz (11 Hz at `hold` = 4), its first null at `1 / (hold · Ts)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dither {
    /// Amplitude, slm (issue 32: at most 1).
    pub amplitude: f32,
    /// Ticks per bit.
    pub hold: u32,
}

/// A sudden change of the lung at the start of a breath.
#[derive(Clone, Debug, PartialEq)]
pub struct LungChange {
    /// The breath (from 0) at whose start the lung changes.
    pub breath: u32,
    /// The lung from then on.
    pub lung: LungParams,
}

/// One study run's settings.
#[derive(Clone, Debug)]
pub struct Study {
    /// The blower and the lung at power-up.
    pub plant: PlantArgs,
    /// Sensor-noise seed (power-up and run).
    pub seed: u64,
    /// The sensor's noise is the default SFM3300 model's times this (0: quantisation and
    /// offset only) during run mode; the power-up identification has the default noise.
    pub noise_x: f64,
    /// Breaths run.
    pub breaths: u32,
    /// Lung changes, in breath order.
    pub changes: Vec<LungChange>,
    /// What is done with the re-estimates.
    pub mode: Mode,
    /// Forgetting shift `k` of the window (`λ = 1 − 2^{−k}` per breath).
    pub shift: u8,
    /// A re-estimate starts every this many breaths (at a boundary, when none is running).
    pub every: u32,
    /// The setpoint dither, if any.
    pub dither: Option<Dither>,
    /// Ridge-M's settings for the re-estimates.
    pub method: RidgeM<f32>,
    /// [`Refit`] units run per tick (the device: 1, see docs/control.md for their cost).
    pub units: u32,
    /// The setpoint program ([`PROGRAM`]: square breaths).
    pub program: Program,
    /// The swap rule ([`swap_allowed`]): an accepted re-estimate replaces the running model
    /// only when the running model's own held-out free-run fit is below this, percent;
    /// `None` (or 100): always.
    pub swap_below_fit: Option<f64>,
}

impl Study {
    /// The adult lung of `plant` (default blower), changing to C 10 mL/cmH₂O, R 50
    /// cmH₂O/(L/s) at breath 10 and back at breath 30, 50 breaths of [`PROGRAM`], adaptive,
    /// `k` = 2, a re-estimate every breath, no dither, the paper's Ridge-M at one unit a tick.
    pub fn lung_change(seed: u64) -> Self {
        let adult = LungParams::adult();
        let stiff = LungParams {
            compliance: 10.0,
            resistance: 50.0,
            ..adult.clone()
        };
        Study {
            plant: PlantArgs::preset(crate::Blower::Default, crate::Outlet::Adult),
            seed,
            noise_x: 1.0,
            breaths: 50,
            changes: vec![
                LungChange {
                    breath: 10,
                    lung: stiff,
                },
                LungChange {
                    breath: 30,
                    lung: adult,
                },
            ],
            mode: Mode::Adapt,
            shift: 2,
            every: 1,
            dither: None,
            method: RidgeM::PAPER,
            units: 1,
            program: PROGRAM,
            swap_below_fit: None,
        }
    }

    /// The re-estimation's settings of this study.
    pub fn rules(&self) -> Rules {
        Rules {
            mode: self.mode,
            every: self.every,
            method: self.method,
            units: self.units,
            swap_below_fit: self.swap_below_fit,
            acceptance: acceptance(),
        }
    }

    /// The lung during breath `b`.
    pub fn lung_at(&self, b: u32) -> LungParams {
        let mut lung = self
            .plant
            .lung()
            .ok()
            .flatten()
            .unwrap_or_else(LungParams::adult);
        for c in &self.changes {
            if c.breath <= b {
                lung = c.lung.clone();
            }
        }
        lung
    }
}

/// The breath program of the study: [`DEMO_BREATH`] (square 10 → 60 slm, 20 /min, I:E 1:2,
/// 0.3 s rise), repeated from run mode's first tick.
pub const PROGRAM: Program = Program::Breath(BreathWave::new(&DEMO_BREATH));

/// Ticks per breath.
pub fn breath_ticks() -> u32 {
    (DEMO_BREATH.period() / ridge_pump_firmware::units::TS_S + 0.5) as u32
}

/// Ticks of a breath counted as its inspiration for the volumes: the inspiration and the
/// square's fall (`T_i + rise`).
pub fn inspiration_ticks() -> u32 {
    ((DEMO_BREATH.inspiration() + DEMO_BREATH.rise) / ridge_pump_firmware::units::TS_S + 0.5) as u32
}

/// One breath's figures (true flow against the program).
#[derive(Clone, Debug, PartialEq)]
pub struct BreathFigures {
    /// Breath number, from 0.
    pub breath: u32,
    /// RMS of true flow minus the programmed setpoint over the breath, slm.
    pub rms: f64,
    /// The programmed volume of the inspiration, mL.
    pub set_ml: f64,
    /// The delivered (true) volume of the inspiration, mL.
    pub delivered_ml: f64,
    /// The static gain of the model the controller was designed from during the breath.
    pub model_gain: f32,
}

impl BreathFigures {
    /// Delivered minus set volume, percent of the set volume.
    pub fn volume_error_pct(&self) -> f64 {
        100.0 * (self.delivered_ml - self.set_ml) / self.set_ml
    }
}

/// One re-estimate and what became of it.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The breath at whose start the window was snapshot.
    pub breath: u32,
    /// The window's weighted rows at the snapshot.
    pub weight: u32,
    /// The estimate, or why there is none (`Refit` refused it); `None` while (or if the run
    /// ended while) fitting.
    pub model: Option<Result<ArxModel<f32>, ridge_core::Error>>,
    /// Ridge-M iterates.
    pub iterations: u32,
    /// The window's RMS response, slm.
    pub response: f32,
    /// The window's RMS input (duty) about its mean, fraction.
    pub input_response: f32,
    /// The verdict: `Ok` the held-out free-run fits (estimate, running model) in percent, `Err`
    /// why it was refused; `None` when the run ended first.
    pub verdict: Option<Result<(f32, f32), Rejection<f32>>>,
    /// Accepted, but the swap rule ([`Rules::swap_below_fit`]) kept the running model.
    pub held: bool,
    /// The breath at whose start the new controller took over (`Mode::Adapt`, accepted, and
    /// the design not refused).
    pub swapped_at: Option<u32>,
    /// The design refused the accepted estimate.
    pub design_refused: bool,
}

/// One run.
#[derive(Clone, Debug)]
pub struct StudyRun {
    /// The power-up switch-over (model, duty, flow).
    pub switchover: Switchover,
    /// Per breath.
    pub breaths: Vec<BreathFigures>,
    /// Every re-estimate, in order.
    pub estimates: Vec<Estimate>,
}

/// The smallest RMS of the window's input (the map's flow) about its mean for a re-estimate,
/// slm: the firmware's ([`ReidConfig::DEFAULT`]'s `min_input_response`, 5). Measured here
/// (`reid-study`): square breaths 10 → 60 slm move it by 22 slm RMS on the adult lung and 35 slm
/// on C 10 R 50; a constant 30 slm setpoint by 2.3–2.7 slm (the sensor noise fed back, with or
/// without a ±1 slm dither), whose estimates rise 20 % too fast.
pub const MIN_INPUT_RESPONSE: f32 = ReidConfig::DEFAULT.min_input_response;

/// The acceptance rules of the study: the firmware's model limits and minimum fit (70 %) and
/// response (1 slm), [`MIN_INPUT_RESPONSE`], one breath of held-out samples.
pub fn acceptance() -> Acceptance<f32> {
    let c = &EXPERIMENT_CONFIG;
    Acceptance {
        model: c.control.model,
        min_response: c.min_response,
        min_input_response: MIN_INPUT_RESPONSE,
        min_fit: c.min_fit,
        holdout_min: breath_ticks(),
    }
}

/// The firmware's controller for `model` (its design, retries and reference model), `None`
/// when refused.
pub fn design(model: &ArxModel<f32>) -> Option<Design<f32>> {
    let c = &EXPERIMENT_CONFIG.control;
    let mut d = firmware_design(model, c)?;
    if c.tau.is_none() {
        d.set_reference(REFERENCE_POLE).ok();
    }
    Some(d)
}

/// [`design`] with the regulation loop's speed `tau` (s) given instead of taken from the
/// model's slow pole (`Spec::tau`, the firmware's retries, each 1.5 times slower), and the
/// firmware's reference model on the setpoint all the same (a re-design at the power-up
/// design's `Design::tau`: the same loop speed and setpoint response, new `R`, `S` for the
/// new model); `None` as [`design`] when `tau` is `None`.
pub fn design_at(model: &ArxModel<f32>, tau: Option<f32>) -> Option<Design<f32>> {
    let Some(tau) = tau else {
        return design(model);
    };
    let c = &EXPERIMENT_CONFIG.control;
    let spec = ridge_core::control::Spec {
        tau: Some(tau),
        ..c.spec()
    };
    let (d, _) = ridge_core::control::design_slower_on_failure(
        model,
        &spec,
        c.tries,
        ridge_pump_firmware::selfid::SLOWDOWN,
        || {},
    );
    let mut d = d.ok()?;
    d.set_reference(REFERENCE_POLE).ok()?;
    Some(d)
}

/// The firmware's running controller (run mode through the static map) with its model (the
/// dynamics from the map's flow) and preview.
#[derive(Clone, Debug)]
pub struct Running {
    /// The model the controller was designed from.
    pub model: ArxModel<f32>,
    /// The controller; its output is the map's flow, slm.
    pub ctrl: Controller<f32>,
    /// Ticks the controller is given the program ahead.
    pub preview: u32,
}

impl Running {
    /// Started bumplessly at the map's flow `v` of the applied duty and the reading `flow`
    /// (slm), with the firmware's duty limits through the map.
    pub fn new(model: ArxModel<f32>, d: &Design<f32>, table: &MapTable, v: f32, flow: f32) -> Self {
        let c = &EXPERIMENT_CONFIG.control;
        let limits = Limits {
            min: map_slm(table, c.duty_min),
            max: map_slm(table, c.duty_max.min(DUTY_FULL_SCALE)),
            max_step: f32::MAX,
        };
        let mut ctrl = Controller::new(d.rst, limits);
        ctrl.start(v, flow);
        Running {
            model,
            ctrl,
            preview: u32::from(preview_ticks(d.mean_delay(&model))),
        }
    }

    /// The controller for `model` (with [`Mode::Restart`], the running model's own design
    /// restarted) started bumplessly at the last output and the reading `y` (slm); `None`
    /// when the design refuses the model.
    pub fn swapped(
        &self,
        model: ArxModel<f32>,
        mode: Mode,
        table: &MapTable,
        y: f32,
    ) -> Option<Self> {
        self.swapped_at(model, mode, table, y, None).map(|(r, _)| r)
    }

    /// [`swapped`](Self::swapped) with the new design's regulation speed `tau` (s;
    /// [`design_at`]), and the design's `tau` as resolved (s).
    pub fn swapped_at(
        &self,
        model: ArxModel<f32>,
        mode: Mode,
        table: &MapTable,
        y: f32,
        tau: Option<f32>,
    ) -> Option<(Self, f32)> {
        let model = if mode == Mode::Restart {
            self.model
        } else {
            model
        };
        let d = design_at(&model, tau)?;
        Some((Running::new(model, &d, table, self.ctrl.last(), y), d.tau))
    }

    /// One control tick of run mode through the map (as `firmware/src/selfid/run.rs`): the
    /// controller's output for the previewed setpoint `ahead` and the reading `y` (slm) is
    /// the map's flow, turned into duty by the map's inverse within the duty limits and the
    /// rate limit from `applied` (1/10 000), and the controller is told the map's flow of the
    /// duty applied. Returns the duty and that flow (counts).
    pub fn tick(&mut self, table: &MapTable, ahead: f32, y: f32, applied: u16) -> (u16, i16) {
        let c = &EXPERIMENT_CONFIG.control;
        let v = self.ctrl.output(ahead, y);
        let duty = duty_for_flow(
            table,
            v,
            applied,
            c.duty_min,
            c.duty_max.min(DUTY_FULL_SCALE),
            c.duty_step,
        );
        let counts = table.at(duty);
        self.ctrl.commit(f32::from(counts) * SLM_PER_COUNT);
        (duty, counts)
    }
}

/// The map's flow at `duty` (1/10 000), slm, as the firmware's run mode converts it.
pub fn map_slm(table: &MapTable, duty: u16) -> f32 {
    f32::from(table.at(duty)) * SLM_PER_COUNT
}

/// Where the current re-estimate stands.
enum Job {
    Idle,
    Fitting(Box<Refit<f32>>, usize),
    HoldingOut(Box<Holdout<f32>>, usize),
}

/// The PRBS bits of a dither.
struct DitherGen {
    d: Dither,
    lfsr: ridge_core::excitation::Lfsr,
    bit: bool,
}

impl DitherGen {
    fn new(d: Dither, seed: u64) -> Option<Self> {
        Some(DitherGen {
            d,
            lfsr: ridge_core::excitation::Lfsr::new(7, (seed as u16) | 1)?,
            bit: false,
        })
    }

    fn at(&mut self, k: u32) -> f32 {
        if k % self.d.hold.max(1) == 0 {
            self.bit = self.lfsr.next_bit();
        }
        if self.bit {
            self.d.amplitude
        } else {
            -self.d.amplitude
        }
    }
}

/// What the re-estimation does with the loop's data: a [`Study`]'s settings
/// ([`Study::rules`]), or a ventilation benchmark cell's ([`crate::vent_bench`]).
#[derive(Clone, Copy, Debug)]
pub struct Rules {
    /// What is done with the re-estimates.
    pub mode: Mode,
    /// A re-estimate starts every this many breaths (at a boundary, when none is running).
    pub every: u32,
    /// Ridge-M's settings for the re-estimates.
    pub method: RidgeM<f32>,
    /// [`Refit`] units run per tick.
    pub units: u32,
    /// The swap rule ([`swap_allowed`]), percent; `None` (or 100 and more): always.
    pub swap_below_fit: Option<f64>,
    /// The checks of an estimate and its verdict.
    pub acceptance: Acceptance<f32>,
}

/// The swap rule: an estimate the [`Acceptance`] accepted replaces the running model only when
/// the running model's own held-out free-run fit (`running_fit`, percent, the verdict's
/// [`HoldoutVerdict::running`](ridge_core::reid::HoldoutVerdict)) is below `swap_below_fit`
/// percent; `None` or a threshold of 100 or more: always (the acceptance alone). A running fit
/// that is not a number is below every threshold.
pub fn swap_allowed(running_fit: f32, swap_below_fit: Option<f64>) -> bool {
    match swap_below_fit {
        Some(x) if x < 100.0 => f64::from(running_fit) < x || running_fit.is_nan(),
        _ => true,
    }
}

/// The re-estimation side of the closed loop, as the firmware would run it beside the
/// controller: the statistics window ([`Window`]), the re-estimate in progress ([`Refit`]),
/// its hold-out ([`Holdout`]) and verdict, and the accepted model waiting for its swap. The
/// loop ([`run`], [`crate::vent_bench`]) calls [`boundary`](Self::boundary) at each breath
/// boundary of the program, [`after_pwm`](Self::after_pwm) each tick after the duty is
/// written, and swaps the controller itself when [`take_pending`](Self::take_pending) gives a
/// model.
pub struct Reestimation<'a> {
    rules: Rules,
    window: Window<'a>,
    job: Job,
    pending: Option<(ArxModel<f32>, usize)>,
    estimates: Vec<Estimate>,
}

/// The statistics window's storage for any structure ([`window_len`] of the largest).
pub type WindowStore = [i64; window_len(ridge_core::PARAMS_MAX)];

impl<'a> Reestimation<'a> {
    /// Re-estimation of `model`'s structure and offset with the forgetting shift `shift`,
    /// the window kept in `store`.
    pub fn new(
        model: &ArxModel<f32>,
        shift: u8,
        rules: Rules,
        store: &'a mut WindowStore,
    ) -> Result<Self, ExperimentError> {
        let window = Window::new(model.structure(), model.offset(), shift, store)
            .map_err(|e| ExperimentError::Plant(format!("window: {e:?}")))?;
        Ok(Reestimation {
            rules,
            window,
            job: Job::Idle,
            pending: None,
            estimates: Vec::new(),
        })
    }

    /// The boundary that starts breath `b` (from 0) of the program: the forgetting, the
    /// verdict of a hold-out that has scored its samples (an accepted estimate the swap rule
    /// lets through waits for its swap), and the next re-estimate.
    pub fn boundary(&mut self, b: u32) {
        let r = self.rules;
        self.window.end_breath();
        if let Job::HoldingOut(h, i) = &self.job {
            if h.verdict()
                .is_some_and(|v| v.candidate.n >= r.acceptance.holdout_min)
            {
                let verdict = r.acceptance.judge(h);
                let i = *i;
                let e = &mut self.estimates[i];
                e.verdict = Some(verdict.map(|v| (v.candidate.fit, v.running.fit)));
                if matches!(r.mode, Mode::Adapt | Mode::Restart) {
                    if let Ok(v) = verdict {
                        if !swap_allowed(v.running.fit, r.swap_below_fit) {
                            e.held = true;
                        } else if let Some(Ok(m)) = e.model {
                            self.pending = Some((m, i));
                        }
                    }
                }
                self.job = Job::Idle;
            }
        }
        if r.mode != Mode::Frozen && matches!(self.job, Job::Idle) && b > 0 && b % r.every == 0 {
            // A window too short for the structure starts nothing (the next boundary tries).
            if let Ok(f) = Refit::start(&self.window, r.method, &MODEL_SCALE) {
                self.estimates.push(Estimate {
                    breath: b,
                    weight: f.weight(),
                    model: None,
                    iterations: 0,
                    response: f.response(),
                    input_response: f.input_response(),
                    verdict: None,
                    held: false,
                    swapped_at: None,
                    design_refused: false,
                });
                self.job = Job::Fitting(Box::new(f), self.estimates.len() - 1);
            }
        }
    }

    /// The accepted model waiting for its swap and its estimate's index, taken.
    pub fn take_pending(&mut self) -> Option<(ArxModel<f32>, usize)> {
        self.pending.take()
    }

    /// Estimate `i`'s controller took over at the start of breath `breath` (`Some`), or the
    /// design refused its model (`None`).
    pub fn swapped(&mut self, i: usize, breath: Option<u32>) {
        if let Some(e) = self.estimates.get_mut(i) {
            match breath {
                Some(b) => e.swapped_at = Some(b),
                None => e.design_refused = true,
            }
        }
    }

    /// After the tick's PWM write: the window takes the map's flow at the written duty
    /// (`v_counts`) and the reading (`counts`); one step of the re-estimate or the hold-out;
    /// `running` is the running controller's model.
    pub fn after_pwm(&mut self, v_counts: i16, counts: i16, running: &ArxModel<f32>) {
        let _ = self.window.push(v_counts, counts);
        let (uk, yk) = (
            f32::from(v_counts) * SLM_PER_COUNT,
            f32::from(counts) * SLM_PER_COUNT,
        );
        let job = std::mem::replace(&mut self.job, Job::Idle);
        self.job = match job {
            Job::Fitting(mut f, i) => match f.step(self.rules.units) {
                RefitStep::Working => Job::Fitting(f, i),
                RefitStep::Done(m, iters) => {
                    let e = &mut self.estimates[i];
                    e.model = Some(Ok(m));
                    e.iterations = iters;
                    match self
                        .rules
                        .acceptance
                        .check_estimate(&m, e.response, e.input_response)
                    {
                        Ok(_) => Job::HoldingOut(Box::new(Holdout::new(m, *running)), i),
                        Err(why) => {
                            e.verdict = Some(Err(why));
                            Job::Idle
                        }
                    }
                }
                RefitStep::Refused(why) => {
                    self.estimates[i].model = Some(Err(why));
                    Job::Idle
                }
            },
            Job::HoldingOut(mut h, i) => {
                h.push(uk, yk);
                Job::HoldingOut(h, i)
            }
            Job::Idle => Job::Idle,
        };
    }

    /// Estimate `i` was accepted but the caller's swap policy kept the running controller
    /// (counted as held, as by [`Rules::swap_below_fit`]).
    pub fn hold(&mut self, i: usize) {
        if let Some(e) = self.estimates.get_mut(i) {
            e.held = true;
        }
    }

    /// Every re-estimate so far, in order.
    pub fn estimates(&self) -> &[Estimate] {
        &self.estimates
    }

    /// Every re-estimate, in order.
    pub fn into_estimates(self) -> Vec<Estimate> {
        self.estimates
    }
}

/// Runs one study: power-up as the firmware, then `study.breaths` breaths.
pub fn run(study: &Study) -> Result<StudyRun, ExperimentError> {
    let (mut rig, _sm, sw) = identify(&study.plant, study.seed)?;
    let sensor = Sfm3300Params::default();
    rig.sensor = Sfm3300::new(
        Sfm3300Params {
            noise_rel: sensor.noise_rel * study.noise_x,
            noise_floor_slm: sensor.noise_floor_slm * study.noise_x,
            ..sensor
        },
        study.seed ^ 0x5eed,
    );
    let d0 = design(&sw.model).ok_or(ExperimentError::Score)?;

    let table = sw.map.table();
    let mut running = Running::new(sw.model, &d0, &table, map_slm(&table, sw.duty), sw.flow);
    let mut applied = sw.duty;
    let mut store: WindowStore = [0; window_len(ridge_core::PARAMS_MAX)];
    let mut reest = Reestimation::new(&sw.model, study.shift, study.rules(), &mut store)?;
    let mut dither = match study.dither {
        Some(d) => Some(DitherGen::new(d, study.seed).ok_or(ExperimentError::Score)?),
        None => None,
    };
    let period = breath_ticks();
    let insp = inspiration_ticks();
    let mut breaths = Vec::new();
    let mut raw = rig.step(sw.duty);
    let (mut sq, mut set_ml, mut got_ml) = (0.0, 0.0, 0.0);
    let mut breath_gain = running.model.static_gain();
    let ticks = study.breaths * period;
    for k in 0..ticks {
        let b = k / period;
        let phase = k % period;
        if phase == 0 {
            // The breath boundary: the last breath's figures, the lung change, the forgetting,
            // the verdict, the next job.
            if b > 0 {
                breaths.push(BreathFigures {
                    breath: b - 1,
                    rms: (sq / f64::from(period)).sqrt(),
                    set_ml,
                    delivered_ml: got_ml,
                    model_gain: breath_gain,
                });
            }
            (sq, set_ml, got_ml) = (0.0, 0.0, 0.0);
            for c in study.changes.iter().filter(|c| c.breath == b) {
                if let Some(lung) = rig.lung.as_mut() {
                    lung.set_params(c.lung.clone());
                }
            }
            reest.boundary(b);
            breath_gain = running.model.static_gain();
        }
        // The swap, at the breath boundary as the controller sees the program (its preview
        // ahead of the program): the setpoint it is given is still the flat end of the
        // expiration, so the new controller's bumpless start at the reading is an equilibrium.
        // At the program's own boundary the previewed setpoint is already rising, and a
        // restarted reference model would lag the breath's rise by the preview.
        if (k + running.preview) % period == 0 {
            if let Some((model, i)) = reest.take_pending() {
                let y = f32::from(raw_to_counts(raw)) * SLM_PER_COUNT;
                match running.swapped(model, study.mode, &table, y) {
                    Some(r) => {
                        running = r;
                        reest.swapped(i, Some(k.div_ceil(period)));
                    }
                    None => reest.swapped(i, None),
                }
            }
        }
        // The control tick.
        let y = f32::from(raw_to_counts(raw)) * SLM_PER_COUNT;
        let mut ahead = setpoint::value(study.program, sw.flow, k + running.preview);
        if let Some(g) = dither.as_mut() {
            ahead += g.at(k);
        }
        let (duty, vk_counts) = running.tick(&table, ahead, y, applied);
        applied = duty;
        let flow = rig.true_flow(duty);
        raw = rig.sensor.measure_raw(flow);
        // After the PWM write: the statistics (the map's flow in, the reading out, counts), one
        // unit of the re-estimate, the hold-out.
        reest.after_pwm(vk_counts, raw_to_counts(raw), &running.model);
        let r = f64::from(setpoint::value(study.program, sw.flow, k));
        sq += (flow - r).powi(2);
        if phase < insp {
            set_ml += r * ML_PER_SLM_TICK;
            got_ml += flow * ML_PER_SLM_TICK;
        }
    }
    breaths.push(BreathFigures {
        breath: study.breaths.saturating_sub(1),
        rms: (sq / f64::from(period)).sqrt(),
        set_ml,
        delivered_ml: got_ml,
        model_gain: breath_gain,
    });
    Ok(StudyRun {
        switchover: sw,
        breaths,
        estimates: reest.into_estimates(),
    })
}

/// Mean and sample standard deviation of `v` (0 for fewer than two values; NaN for none).
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (mean, var.sqrt())
}

/// The re-estimates of `run` snapshot at breaths `from..to` that produced a model passing the
/// model check of the design (stable, gain in range; [`acceptance`]'s limits), whatever the
/// other checks said.
pub fn models_in(run: &StudyRun, from: u32, to: u32) -> Vec<ArxModel<f32>> {
    run.estimates
        .iter()
        .filter(|e| e.breath >= from && e.breath < to)
        .filter_map(|e| e.model.and_then(Result::ok))
        .filter(|m| ridge_core::control::check_model(m, &acceptance().model).is_ok())
        .collect()
}

/// The breaths `from..to` of `run`.
pub fn breaths_in(run: &StudyRun, from: u32, to: u32) -> Vec<&BreathFigures> {
    run.breaths
        .iter()
        .filter(|b| b.breath >= from && b.breath < to)
        .collect()
}

/// The secant gain of the noise-free plant between the breath's two flows (10 and 60 slm),
/// slm per duty fraction.
pub fn secant_gain(lo: &Linearisation, hi: &Linearisation) -> f64 {
    (hi.flow - lo.flow) / (hi.duty - lo.duty)
}
