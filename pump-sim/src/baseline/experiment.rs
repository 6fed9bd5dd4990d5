//! The three-controller experiment: the firmware identifies the plant and designs its RST
//! controller exactly as on the device; at the switch-over to run mode the rig (and with it
//! the sensor's noise generator) is cloned, and the same setpoint program is tracked from the
//! same state by
//!
//! - **RST**: the firmware's run mode itself (the state machine keeps ticking);
//! - **ZN PID**: [`Pid`] with the Ziegler–Nichols tuning of the noise-free plant
//!   ([`tune_zn`]);
//! - **SIMC PI**: [`Pid`] with the SIMC tuning of an FOPDT fit of the firmware's identified
//!   model ([`fit_model`], [`simc_pi`]).
//!
//! Every controller reads the same sensor words (same noise sequence, as long as the flows are
//! the same: the noise is drawn per sample and scaled by the flow), gets the program
//! [`SelfIdentification::preview`] ticks ahead as the firmware does, and starts bumplessly from
//! the duty and reading at the switch-over. The baselines run at the firmware's duty limits
//! and rate limit ([`firmware_limits`]), with the duty rounded to counts as the firmware
//! rounds it. Every controller is scored against the program itself ([`score`]).
//!
//! Each case is run twice from the same switch-over: with the sensor's noise, and again with a
//! noise-free sensor ([`noise_free_sensor`]: offset and quantisation only) for the step shape,
//! which the noise would otherwise dominate (see [`super::table`]).
//!
//! # Timing
//! Run-mode tick `k` (0 at the first tick after the switch-over) reads the flow at the end of
//! interval `k − 1` (interval −1 runs at the switch-over duty) and sets the duty of interval
//! `k`, whose programmed setpoint is `value(program, start, k)`. [`Trace`] index `k` is
//! interval `k`: the duty applied during it, the flow at its end and its setpoint.

use ridge_core::control::{design_slower_on_failure, Design};
use ridge_core::{ArxModel, InputMap};
use ridge_pump_firmware::event::{Event, LINE_MAX};
use ridge_pump_firmware::selfid::{
    preview_ticks, Config, ControlConfig, SelfIdentification, State, SLOWDOWN,
};
use ridge_pump_firmware::setpoint::{self, Program, DEMO_BREATH, DEMO_HOLD_TICKS, DEMO_STEPS};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::DUTY_FULL_SCALE;

use super::metrics::{rms_error, step_metrics, total_variation, StepMetrics};
use super::pid::{firmware_limits, Pid, PidError, PidGains};
use super::simc::{fit_model, simc_pi, Fopdt, Simc};
use super::stepped::fraction_to_duty;
use super::zn::{relay_test, ultimate, zn_pid, Ultimate, ZnError, ZnSearch};
use crate::sfm3300::raw_to_flow;
use crate::{PlantArgs, Rig, Sfm3300, Sfm3300Params, TS_S};

/// The controllers compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Controller {
    /// The firmware's pole-placement RST, designed on the device from the identified model.
    Rst,
    /// PID tuned by Ziegler–Nichols from the ultimate gain and period.
    ZnPid,
    /// PI tuned by SIMC from an FOPDT fit of the identified model.
    SimcPi,
}

impl Controller {
    /// Every controller, in the order of the tables and of [`CaseRun::traces`].
    pub const ALL: [Controller; 3] = [Controller::Rst, Controller::ZnPid, Controller::SimcPi];

    /// The position in [`Controller::ALL`].
    pub fn index(self) -> usize {
        match self {
            Controller::Rst => 0,
            Controller::ZnPid => 1,
            Controller::SimcPi => 2,
        }
    }

    /// The name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Controller::Rst => "RST (device)",
            Controller::ZnPid => "ZN PID",
            Controller::SimcPi => "SIMC PI",
        }
    }
}

/// Breaths of [`DEMO_BREATH`] run after the steps; the first is not scored (it starts from
/// the last step's level).
pub const BREATHS: u32 = 6;

/// Samples of one breath of [`DEMO_BREATH`] (the program's rounding of its period).
pub fn breath_ticks() -> u32 {
    (DEMO_BREATH.period() / ridge_pump_firmware::units::TS_S + 0.5) as u32
}

/// Samples of the step part of the demo program.
pub fn steps_ticks() -> u32 {
    DEMO_STEPS.iter().map(|l| u32::from(l.ticks)).sum()
}

/// Samples of run mode simulated per controller: the demo's hold, its steps and [`BREATHS`]
/// breaths.
pub fn run_ticks() -> u32 {
    DEMO_HOLD_TICKS + steps_ticks() + BREATHS * breath_ticks()
}

/// The settings the experiment runs the firmware with: [`DEFAULT_CONFIG`](ridge_pump_firmware::selfid::DEFAULT_CONFIG) with the
/// frozen-sensor check off (`frozen_ticks` 0). The noise-free replay's sensor
/// ([`noise_free_sensor`]) reads the same word tick after tick once the loop has settled, which
/// the check would take for a frozen sensor (`FAULT sensor=frozen`) and leave run mode; with
/// the sensor's noise (σ ≥ 7 counts at 2 slm) 50 equal readings in a row do not happen, so the
/// noisy runs are those of the default settings.
pub static EXPERIMENT_CONFIG: Config = Config {
    frozen_ticks: 0,
    ..Config::DEFAULT
};

/// Ticks allowed for the identification and design before run mode (200 s).
pub const IDENTIFY_MAX_TICKS: u32 = 20_000;

/// Ultimate-gain search of the ZN tuning ([`ZnSearch::DEFAULT`]: around 40 slm).
pub const ZN_SEARCH: ZnSearch = ZnSearch::DEFAULT;

/// Relay amplitude of the cross-check relay test, duty fraction (±2 %).
pub const RELAY_H: f64 = 0.02;

/// Why a case could not be run.
#[derive(Clone, Debug, PartialEq)]
pub enum ExperimentError {
    /// The plant options are invalid.
    Plant(String),
    /// The firmware did not reach run mode: its event lines.
    Identification(Vec<String>),
    /// The firmware left run mode during the comparison (drift re-identification, fault):
    /// the tick and the event.
    LeftRun(u32, String),
    /// The identified model has no FOPDT fit (gain not positive or no settling).
    Fopdt,
    /// The ultimate gain was not found.
    Zn(ZnError),
    /// A PID could not be built from its tuning.
    Pid(PidError),
    /// A trace could not be scored (shorter than the program, or a preview longer than a
    /// level).
    Score,
}

impl std::fmt::Display for ExperimentError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ExperimentError::Plant(e) => write!(f, "plant: {e}"),
            ExperimentError::Identification(ev) => {
                write!(f, "no run mode; events: {}", ev.join(" | "))
            }
            ExperimentError::LeftRun(k, e) => write!(f, "firmware left run mode at tick {k}: {e}"),
            ExperimentError::Fopdt => f.write_str("identified model has no FOPDT fit"),
            ExperimentError::Zn(e) => write!(f, "Ziegler-Nichols: {e}"),
            ExperimentError::Pid(e) => write!(f, "PID: {e}"),
            ExperimentError::Score => f.write_str("a trace could not be scored"),
        }
    }
}

impl std::error::Error for ExperimentError {}

/// The Ziegler–Nichols tuning of a plant: the exact ultimate gain, the relay cross-check and
/// the PID gains.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZnTuning {
    /// `K_u` (duty fraction per slm) and `T_u` (s) from the proportional-loop search.
    pub ultimate: Ultimate,
    /// The relay test's `K_u = 4h/(πa)` and `T_u`, `None` when it did not oscillate.
    pub relay: Option<Ultimate>,
    /// `K_p = 0.6 K_u`, `T_i = T_u/2`, `T_d = T_u/8`.
    pub gains: PidGains,
}

/// Ziegler–Nichols tuning of `plant` on the noise-free rig around [`ZN_SEARCH`]'s operating
/// point (see [`super::zn`]).
pub fn tune_zn(plant: &PlantArgs) -> Result<ZnTuning, ExperimentError> {
    let rig = plant
        .rig(Sfm3300Params::ideal(), 0)
        .map_err(ExperimentError::Plant)?;
    let u = ultimate(&rig, &ZN_SEARCH, TS_S).map_err(ExperimentError::Zn)?;
    Ok(ZnTuning {
        ultimate: u,
        relay: relay_test(&rig, &ZN_SEARCH, RELAY_H, TS_S).ok(),
        gains: zn_pid(&u),
    })
}

/// The firmware's design for `model` before its reference model is set: `ridge_core`'s, in
/// `f32`, from the settings' [`ControlConfig::spec`] with the firmware's retries; `None` when
/// refused.
pub fn firmware_design(model: &ArxModel<f32>, c: &ControlConfig) -> Option<Design<f32>> {
    let (design, _) = design_slower_on_failure(model, &c.spec(), c.tries, SLOWDOWN, || {});
    design.ok()
}

/// The preview the firmware's controller would have without its reference model (see
/// [`Switchover::baseline_preview`]): [`firmware_design`]'s mean delay in the firmware's
/// [`preview_ticks`]; 0 if the design fails (it did not: run mode started).
pub fn regulation_preview(model: &ArxModel<f32>, config: &Config) -> u8 {
    firmware_design(model, &config.control).map_or(0, |d| preview_ticks(d.mean_delay(model)))
}

/// The FOPDT fit of the identified model linearised at the duty `duty` (1/10 000), the
/// baselines' plant model in slm per duty fraction: the dynamics' fit ([`fit_model`], gain
/// slm per slm of the map's flow) times the map's slope around `duty` (its segment's, slm
/// per unit duty).
pub fn linearised(model: &ArxModel<f32>, map: &InputMap, duty: u16) -> Option<Fopdt> {
    let mut f = fit_model(model, TS_S)?;
    let half = map.step() / 2;
    let rise =
        f64::from(map.at(duty.saturating_add(half))) - f64::from(map.at(duty.saturating_sub(half)));
    let slope = rise / 120.0 / (f64::from(map.step()) / f64::from(DUTY_FULL_SCALE));
    f.k *= slope;
    Some(f)
}

/// The state at the switch-over to run mode.
#[derive(Clone, Debug)]
pub struct Switchover {
    /// The duty applied at the switch-over (base duty), 1/10 000.
    pub duty: u16,
    /// The flow reading at the switch-over, slm: the start of the program.
    pub flow: f32,
    /// Ticks of setpoint preview of the RST ([`SelfIdentification::preview`]: its setpoint
    /// response's mean delay, the reference model's included).
    pub preview: u8,
    /// Ticks of setpoint preview of the baselines: the firmware's design's mean delay
    /// without its reference model, `d + 1 + Σ k φₖ / Σ φₖ + α / (1 − α)` ([`regulation_preview`]):
    /// the response time the plant-derived design targets, not the RST's deliberately slower
    /// 0.08 s reference, which would give the PIDs their setpoint late.
    pub baseline_preview: u8,
    /// The identified model's dynamics (from the map's flow, slm per slm).
    pub model: ArxModel<f32>,
    /// The identified model's static map from duty (1/10 000) to flow (counts).
    pub map: InputMap,
    /// The tick of the switch-over since power-up.
    pub tick: u32,
    /// Every event line up to the switch-over (`CTRL …` last).
    pub events: Vec<String>,
}

/// What one controller did in run mode, per interval `k` (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    /// The programmed setpoint of interval `k`, slm.
    pub setpoint: Vec<f64>,
    /// The true flow at the end of interval `k`, slm.
    pub flow: Vec<f64>,
    /// The sensor's reading at the end of interval `k`, slm.
    pub measured: Vec<f64>,
    /// The duty applied during interval `k`, 1/10 000.
    pub duty: Vec<u16>,
}

/// One plant, one seed: the identification, the tunings and the three traces.
#[derive(Clone, Debug)]
pub struct CaseRun {
    /// The plant.
    pub plant: PlantArgs,
    /// Sensor-noise seed.
    pub seed: u64,
    /// The firmware at the switch-over.
    pub switchover: Switchover,
    /// FOPDT fit of the identified model.
    pub fopdt: Fopdt,
    /// SIMC tuning from it.
    pub simc: Simc,
    /// Ziegler–Nichols tuning of the plant.
    pub zn: ZnTuning,
    /// Traces in the order of [`Controller::ALL`], with the sensor's noise.
    pub traces: [Trace; 3],
    /// The same runs from the same switch-over state with a noise-free sensor
    /// ([`noise_free_sensor`]), in the order of [`Controller::ALL`].
    pub clean: [Trace; 3],
}

impl CaseRun {
    /// The trace of `c` with sensor noise.
    pub fn trace(&self, c: Controller) -> &Trace {
        &self.traces[c.index()]
    }

    /// The trace of `c` with the noise-free sensor.
    pub fn clean_trace(&self, c: Controller) -> &Trace {
        &self.clean[c.index()]
    }
}

/// The sensor of the noise-free replays: the default zero offset (0.1 slm) and the 1/120 slm
/// quantisation, no noise.
pub fn noise_free_sensor() -> Sfm3300Params {
    Sfm3300Params {
        noise_rel: 0.0,
        noise_floor_slm: 0.0,
        ..Sfm3300Params::default()
    }
}

fn line(e: &Event) -> String {
    e.line::<LINE_MAX>().as_str().to_owned()
}

/// The firmware's board loop after a tick: judgement, search, design; their events go to
/// `events`. Returns `true` when a design latched a fault.
fn main_loop(sm: &mut SelfIdentification, events: &mut Vec<String>) -> bool {
    if let Some(e) = sm.judge() {
        events.push(line(&e));
    }
    if let Some(job) = sm.take_search() {
        let outcome = job.run(|| {});
        if let Some(e) = sm.finish_search(outcome) {
            events.push(line(&e));
        }
    }
    if let Some(e) = sm.design(|| {}) {
        events.push(line(&e));
        return sm.fault().is_some();
    }
    false
}

/// Powers up the firmware's state machine on `plant` with sensor-noise seed `seed` and runs
/// it as the board does until run mode starts: the rig and the machine at the switch-over.
pub fn identify(
    plant: &PlantArgs,
    seed: u64,
) -> Result<(Rig, SelfIdentification, Switchover), ExperimentError> {
    identify_with(plant, seed, &EXPERIMENT_CONFIG)
}

/// [`identify`] with the firmware's settings `config` instead of [`EXPERIMENT_CONFIG`].
pub fn identify_with(
    plant: &PlantArgs,
    seed: u64,
    config: &'static Config,
) -> Result<(Rig, SelfIdentification, Switchover), ExperimentError> {
    let mut rig = plant
        .rig(Sfm3300Params::default(), seed)
        .map_err(ExperimentError::Plant)?;
    let mut sm = SelfIdentification::new(config, None);
    let mut duty = 0u16;
    let mut events = Vec::new();
    for tick in 0..IDENTIFY_MAX_TICKS {
        let raw = rig.step(duty);
        let t = sm.tick(Ok(raw_to_counts(raw)));
        duty = t.duty;
        if let Some(e) = t.event {
            events.push(line(&e));
        }
        if main_loop(&mut sm, &mut events) {
            duty = 0;
        }
        match sm.state() {
            State::Run => {
                let (Some(flow), Some(preview), Some(model), Some(map)) = (
                    sm.setpoint(),
                    sm.preview(),
                    sm.model().copied(),
                    sm.map().copied(),
                ) else {
                    break;
                };
                let sw = Switchover {
                    duty: sm.duty(),
                    flow,
                    preview,
                    baseline_preview: regulation_preview(&model, config),
                    model,
                    map,
                    tick,
                    events,
                };
                return Ok((rig, sm, sw));
            }
            State::Fault => break,
            _ => {}
        }
    }
    Err(ExperimentError::Identification(events))
}

/// Runs one controller for [`run_ticks`] intervals from `rig` at the switch-over: `next(k,
/// raw)` gets the sensor word at the end of interval `k − 1` and returns the duty of interval
/// `k`.
pub fn run_loop(
    rig: &mut Rig,
    sw: &Switchover,
    program: Program,
    mut next: impl FnMut(u32, u16) -> Result<u16, ExperimentError>,
) -> Result<Trace, ExperimentError> {
    let n = run_ticks() as usize;
    let mut tr = Trace {
        setpoint: Vec::with_capacity(n),
        flow: Vec::with_capacity(n),
        measured: Vec::with_capacity(n),
        duty: Vec::with_capacity(n),
    };
    let mut raw = rig.step(sw.duty);
    for k in 0..run_ticks() {
        let duty = next(k, raw)?.min(DUTY_FULL_SCALE);
        let flow = rig.true_flow(duty);
        raw = rig.sensor.measure_raw(flow);
        tr.setpoint
            .push(f64::from(setpoint::value(program, sw.flow, k)));
        tr.flow.push(flow);
        tr.measured.push(raw_to_flow(raw));
        tr.duty.push(duty);
    }
    Ok(tr)
}

/// The firmware's own run mode from the switch-over.
fn run_rst(
    rig: &mut Rig,
    sm: &mut SelfIdentification,
    sw: &Switchover,
    program: Program,
) -> Result<Trace, ExperimentError> {
    let mut events = Vec::new();
    run_loop(rig, sw, program, |k, raw| {
        let t = sm.tick(Ok(raw_to_counts(raw)));
        let mut event = t.event.as_ref().map(line);
        let faulted = main_loop(sm, &mut events);
        if sm.state() != State::Run || faulted {
            if let Some(e) = events.pop() {
                event = Some(e);
            }
            return Err(ExperimentError::LeftRun(
                k,
                event.unwrap_or_else(|| format!("{:?}", sm.state())),
            ));
        }
        Ok(t.duty)
    })
}

/// A baseline [`Pid`] with `gains` from the switch-over, given the program `preview` ticks
/// ahead.
fn run_pid(
    rig: &mut Rig,
    sw: &Switchover,
    program: Program,
    gains: PidGains,
) -> Result<Trace, ExperimentError> {
    let mut pid = Pid::new(gains, firmware_limits(), TS_S).map_err(ExperimentError::Pid)?;
    pid.start(
        f64::from(sw.duty) / f64::from(DUTY_FULL_SCALE),
        f64::from(sw.flow),
    );
    let preview = u32::from(sw.baseline_preview);
    run_loop(rig, sw, program, |k, raw| {
        let r = f64::from(setpoint::value(program, sw.flow, k.saturating_add(preview)));
        Ok(fraction_to_duty(pid.step(r, raw_to_flow(raw))))
    })
}

/// The three controllers from the switch-over state `rig`, `sm`, `sw`.
fn run_all(
    rig: &Rig,
    sm: &SelfIdentification,
    sw: &Switchover,
    zn: PidGains,
    simc: PidGains,
) -> Result<[Trace; 3], ExperimentError> {
    let program = sm.config().control.program;
    let rst = run_rst(&mut rig.clone(), &mut sm.clone(), sw, program)?;
    let znt = run_pid(&mut rig.clone(), sw, program, zn)?;
    let simct = run_pid(&mut rig.clone(), sw, program, simc)?;
    Ok([rst, znt, simct])
}

/// One case: identification on `plant` with noise seed `seed`, then the three controllers
/// from the switch-over (`zn`: the plant's Ziegler–Nichols tuning, from [`tune_zn`]), with the
/// sensor's noise and again with a noise-free sensor.
pub fn run_case(plant: &PlantArgs, seed: u64, zn: &ZnTuning) -> Result<CaseRun, ExperimentError> {
    run_case_with(plant, seed, zn, &EXPERIMENT_CONFIG)
}

/// [`run_case`] with the firmware's settings `config` instead of [`EXPERIMENT_CONFIG`].
pub fn run_case_with(
    plant: &PlantArgs,
    seed: u64,
    zn: &ZnTuning,
    config: &'static Config,
) -> Result<CaseRun, ExperimentError> {
    run_identified(plant, seed, zn, identify_with(plant, seed, config)?)
}

/// [`run_case`] from a switch-over already reached ([`identify`]'s result for the same
/// `plant` and `seed`), for callers that also run other controllers from it.
pub fn run_identified(
    plant: &PlantArgs,
    seed: u64,
    zn: &ZnTuning,
    (rig, sm, sw): (Rig, SelfIdentification, Switchover),
) -> Result<CaseRun, ExperimentError> {
    let fopdt = linearised(&sw.model, &sw.map, sw.duty).ok_or(ExperimentError::Fopdt)?;
    let simc = simc_pi(&fopdt, TS_S).ok_or(ExperimentError::Fopdt)?;
    let traces = run_all(&rig, &sm, &sw, zn.gains, simc.gains)?;
    let mut quiet = rig;
    quiet.sensor = Sfm3300::new(noise_free_sensor(), seed);
    let clean = run_all(&quiet, &sm, &sw, zn.gains, simc.gains)?;
    Ok(CaseRun {
        plant: plant.clone(),
        seed,
        switchover: sw,
        fopdt,
        simc,
        zn: *zn,
        traces,
        clean,
    })
}

/// The scores of one trace. Flows in slm, times in s.
#[derive(Clone, Debug, PartialEq)]
pub struct Scores {
    /// One per level of [`DEMO_STEPS`] (the first from the start flow), `None` where the
    /// metrics are undefined.
    pub steps: Vec<Option<StepMetrics>>,
    /// The level of each step, slm.
    pub levels: Vec<f64>,
    /// RMS of `setpoint − flow` over the scored breaths (all but the first), slm.
    pub breath_rms: f64,
    /// Duty total variation `Σ|Δu|` per second over the whole run, duty fraction per s.
    pub duty_tv: f64,
}

/// Scores a trace against its program setpoints, from the true flow or (`measured`) from the
/// sensor's readings; `preview` is the setpoint preview the controllers had, in ticks.
///
/// Step `j` of [`DEMO_STEPS`] at tick `s_j` is scored on the window from `s_j − preview` to
/// `s_{j+1} − preview` (`s_4`: the start of the breaths): with the preview the controllers see
/// a step that many ticks early, so the flow may move before it (counted in the IAE against the
/// old setpoint) and leaves the level that early (not counted against the level's overshoot,
/// settling and steady state). `None` when the trace is shorter than [`run_ticks`] or the
/// preview is longer than a level.
pub fn score(tr: &Trace, measured: bool, preview: u32) -> Option<Scores> {
    let y = if measured { &tr.measured } else { &tr.flow };
    if y.len() < run_ticks() as usize || tr.setpoint.len() < y.len() {
        return None;
    }
    let p = preview as usize;
    if DEMO_STEPS.iter().any(|l| usize::from(l.ticks) <= p) || DEMO_HOLD_TICKS as usize <= p {
        return None;
    }
    let mut steps = Vec::new();
    let mut levels = Vec::new();
    let mut prev_start = 0usize;
    let mut start = DEMO_HOLD_TICKS as usize;
    for l in DEMO_STEPS {
        let end = start + usize::from(l.ticks);
        let from = tr.setpoint[start - 1];
        let to = tr.setpoint[start];
        steps.push(step_metrics(
            &y[prev_start..end - p],
            start - prev_start,
            p,
            from,
            to,
            TS_S,
        ));
        levels.push(to);
        prev_start = start;
        start = end;
    }
    let breath = (DEMO_HOLD_TICKS + steps_ticks() + breath_ticks()) as usize;
    let n = run_ticks() as usize;
    let breath_rms = rms_error(&y[breath..n], &tr.setpoint[breath..n])?;
    let u: Vec<f64> = tr
        .duty
        .iter()
        .map(|&d| f64::from(d) / f64::from(DUTY_FULL_SCALE))
        .collect();
    Some(Scores {
        steps,
        levels,
        breath_rms,
        duty_tv: total_variation(&u, TS_S)?,
    })
}
