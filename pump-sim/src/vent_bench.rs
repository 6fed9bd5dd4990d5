//! The ventilation benchmark (issue 32, *Targets*): volume-controlled breaths on the ISO
//! 80601-2-12 test lungs ([`crate::iso`]) under four flow controllers, scored on the lung's
//! own truth.
//!
//! One cell ([`Cell`]) is one ISO row's lung and breath, one inspiratory wave, one controller
//! ([`Ctrl`]), one sensor-noise seed:
//!
//! - **power-up** ([`power_up`]): the firmware's state machine identifies the default blower
//!   into the row's lung with its PEEP valve at 0 cmH₂O (as the simavr bench does: at the row's
//!   PEEP the identification's low steps cannot open the valve) and designs its controller
//!   ([`crate::baseline::experiment::identify`]); the SFM3300 noise model is on throughout.
//!   At the switch-over the operator sets the row's PEEP valve and the `VENT` command starts.
//! - **the breaths**: the firmware's own `VENT` settings ([`ventilation::settings`]: VT, rate,
//!   `ti` 1 s, the row's PEEP, the default bias flow 5 slm and rise 0.1 s, the wave, the trim
//!   on as the firmware's default), its own program ([`Setpoint`] with the [`VolumeWave`]), its
//!   own per-breath bookkeeping ([`Ventilation`]: delivered volume from the readings, the trim)
//!   and its own exhalation valve (closed in the inspiration), tick by tick in run mode's order.
//! - **the controllers**, from the same switch-over state (rig and noise stream cloned):
//!   [`Ctrl::Adaptive`] the firmware's RST with the closed-loop re-identification of
//!   [`crate::reid`] (a re-estimate every breath, judged on one breath held out, re-designed
//!   and swapped at the breath boundary as the controller sees it); [`Ctrl::Frozen`] the same
//!   power-up design, never re-designed; [`Ctrl::Simc`] and [`Ctrl::Zn`] the baselines'
//!   [`Pid`] in duty at the firmware's limits, given the program
//!   [`Switchover::baseline_preview`] ticks ahead ([`crate::baseline::experiment`]): SIMC PI
//!   from an FOPDT fit of the power-up model linearised at the switch-over duty
//!   ([`linearised`]), Ziegler–Nichols PID from the ultimate gain of the noise-free plant
//!   (proportional-loop search at 40 slm on the power-up lung, [`tune_zn`]).
//! - **the truth** per breath ([`Breath`]): the volume the lung gained while the valve was
//!   closed, the largest airway pressure at the blower's outlet (sampled at the end of each
//!   tick), the lung pressure at the end of the expiration (the PEEP), and the firmware's own
//!   `BREATH` figures beside them.
//! - **lung changes** ([`LungChange`]): at a breath boundary or half-way through a breath's
//!   inspiration; [`change_verdict`]: a run against the targets after one.
//! - **the swap policy** of the adaptive controller ([`Policy`], study knobs; today's by
//!   default): when an accepted re-estimate is swapped in ([`SwapWhen`]: always, never, on the
//!   volume alarm, above a tracking RMS), at which regulation speed it is re-designed, the
//!   window's forgetting, the trim restarted at a swap, a wait for breaths of the new lung.
//! - **the model of the breath's plant** the adaptive controller re-estimates ([`BreathPlant`],
//!   study knobs; the firmware's by default): the window fed every tick or each inspiration
//!   only, with extra lags, the model check, the re-design's kept poles, the held-out fit's
//!   floor, a setpoint dither; [`run_cell_figures`] adds each breath's inspiration-only tracking RMS.
//!
//! [`Setpoint`]: ridge_pump_firmware::setpoint::Setpoint
//! [`VolumeWave`]: ridge_pump_firmware::setpoint::VolumeWave

use ridge_core::control::ModelLimits;
use ridge_core::reid::window_len;
use ridge_pump_firmware::command::VentArgs;
use ridge_pump_firmware::event::Event;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::{Program, Setpoint, Shape, VolumeBreath};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, SLM_PER_COUNT};
use ridge_pump_firmware::ventilation::{self, Ventilation};

use crate::baseline::experiment::{
    identify, linearised, tune_zn, ExperimentError, Switchover, ZnTuning,
};
use crate::baseline::pid::{firmware_limits, Pid, PidGains};
use crate::baseline::simc::simc_pi;
use crate::baseline::stepped::fraction_to_duty;
use crate::iso::{IsoRow, ISO_ROWS};
use crate::reid::{
    acceptance, design, map_slm, Dither, DitherGen, Estimate, Feed, Mode, Reestimation, Rules,
    Running, WindowStore,
};
use crate::sfm3300::raw_to_flow;
use crate::{Blower, LungParams, Outlet, PlantArgs, Rig, Valve, TS_S};

/// The controllers compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ctrl {
    /// The firmware's RST, re-identified and re-designed at breath boundaries.
    Adaptive,
    /// The firmware's RST of the power-up design, never re-designed.
    Frozen,
    /// SIMC PI from the power-up model.
    Simc,
    /// Ziegler–Nichols PID from the noise-free plant's ultimate gain.
    Zn,
}

impl Ctrl {
    /// Every controller, in the tables' order.
    pub const ALL: [Ctrl; 4] = [Ctrl::Adaptive, Ctrl::Frozen, Ctrl::Simc, Ctrl::Zn];

    /// The name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Ctrl::Adaptive => "adaptive",
            Ctrl::Frozen => "frozen",
            Ctrl::Simc => "SIMC PI",
            Ctrl::Zn => "ZN PID",
        }
    }
}

/// Where in its breath a lung change happens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChangeAt {
    /// At the breath boundary: before the breath's first interval (the valve closing).
    Boundary,
    /// Half-way through the breath's inspiration (`N_i / 2` ticks after the boundary).
    Mid,
}

/// A sudden change of the lung.
#[derive(Clone, Debug, PartialEq)]
pub struct LungChange {
    /// The breath (from 1, the firmware's numbering) in which it happens.
    pub breath: u32,
    /// Where in that breath.
    pub at: ChangeAt,
    /// The lung from then on (its PEEP valve included).
    pub lung: LungParams,
}

/// A lung change of the lung-change tables: its name, `(C, R)` before and after (mL/cmH₂O,
/// cmH₂O/(L/s)); the PEEP valve and the rest are row 1's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NamedChange {
    /// As the tables print it, e.g. `C 50 → 10`.
    pub name: &'static str,
    /// The lung at power-up.
    pub from: (f64, f64),
    /// The lung from the change on.
    pub to: (f64, f64),
}

const fn named(name: &'static str, from: (f64, f64), to: (f64, f64)) -> NamedChange {
    NamedChange { name, from, to }
}

/// The lung changes of the lung-change tables (`vent-bench --table changes` on the host,
/// `avr-vent-bench --table changes` on the ATmega2560 image), on row 1's breath: the C
/// 50 → 10, R 5 → 50, both, and each reverse.
pub const CHANGES: [NamedChange; 6] = [
    named("C 50 → 10", (50.0, 5.0), (10.0, 5.0)),
    named("R 5 → 50", (50.0, 5.0), (50.0, 50.0)),
    named("C 50 → 10 and R 5 → 50", (50.0, 5.0), (10.0, 50.0)),
    named("C 10 → 50", (10.0, 5.0), (50.0, 5.0)),
    named("R 50 → 5", (50.0, 50.0), (50.0, 5.0)),
    named("C 10 → 50 and R 50 → 5", (10.0, 50.0), (50.0, 5.0)),
];

/// The breath in which the lung changes in the lung-change tables (counted from 1; the change
/// breath is 1 in their "breaths after" counts).
pub const CHANGE_BREATH: u32 = 6;
/// Breaths run in the lung-change tables.
pub const CHANGE_RUN: u32 = 14;

/// Row 1's lung (behind the adult exhalation valve, PEEP valve at row 1's PEEP) with the
/// compliance `c` (mL/cmH₂O) and resistance `r` (cmH₂O/(L/s)): the lung-change tables' lungs.
pub fn row1_lung(c: f64, r: f64) -> LungParams {
    LungParams {
        compliance: c,
        resistance: r,
        ..row_lung(&ISO_ROWS[0], ISO_ROWS[0].peep)
    }
}

/// Row 1's square breath under `ctrl` on the lung `from` (`(C, R)`), changed to `to` in
/// breath [`CHANGE_BREATH`] (`at`) of [`CHANGE_RUN`]: the lung-change tables' cell.
pub fn change_cell(from: (f64, f64), to: (f64, f64), at: ChangeAt, ctrl: Ctrl) -> Cell {
    let row = IsoRow {
        compliance: from.0,
        resistance: from.1,
        ..ISO_ROWS[0]
    };
    Cell {
        breaths: CHANGE_RUN,
        changes: vec![LungChange {
            breath: CHANGE_BREATH,
            at,
            lung: row1_lung(to.0, to.1),
        }],
        ..Cell::new(row, Shape::Square, ctrl)
    }
}

/// One benchmark run's settings (see the [module docs](self)).
#[derive(Clone, Debug)]
pub struct Cell {
    /// The ISO row: the lung at power-up and the breath.
    pub row: IsoRow,
    /// The inspiratory flow shape.
    pub wave: Shape,
    /// The controller.
    pub ctrl: Ctrl,
    /// Breaths run.
    pub breaths: u32,
    /// Lung changes, in breath order.
    pub changes: Vec<LungChange>,
    /// The per-breath volume trim (`VENT … trim=on`, the firmware's default).
    pub trim: bool,
    /// The adaptive controller's swap rule ([`crate::reid::swap_allowed`]), percent; `None`:
    /// always.
    pub swap_below_fit: Option<f64>,
    /// The adaptive controller's swap policy (study knobs; [`Policy::ALWAYS`], today's, by
    /// default).
    pub policy: Policy,
    /// The adaptive controller's model of the breath's plant (study knobs;
    /// [`BreathPlant::TODAY`], the firmware's, by default).
    pub breath_plant: BreathPlant,
}

/// The adaptive controller's model of the breath's plant (the breath-plant study,
/// docs/control.md): which ticks its re-estimation takes and at which structure ([`Feed`]), and
/// the model check its estimates pass. Applies to [`Ctrl::Adaptive`] only.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BreathPlant {
    /// The window's ticks and structure.
    pub feed: Feed,
    /// The model check of the estimates (`Acceptance::model`); `None`: the firmware's.
    pub model_limits: Option<ModelLimits<f32>>,
    /// The re-design keeps the model's poles within this radius (`Spec::keep_radius`; `None`:
    /// the firmware's 0.8); applies with [`Policy::fixed_speed`].
    pub keep_radius: Option<f32>,
    /// The held-out free-run fit an estimate needs (`Acceptance::min_fit`, percent; `None`:
    /// the firmware's 70); it must beat the running model's all the same.
    pub min_fit: Option<f32>,
    /// A PRBS dither added to the controller's previewed setpoint on every tick (the RST
    /// loops; its LFSR seeded from the power-up's seed), as the re-identification study's.
    pub dither: Option<Dither>,
}

impl BreathPlant {
    /// The firmware's: every tick, the power-up structure, its model check.
    pub const TODAY: BreathPlant = BreathPlant {
        feed: Feed::ALL,
        model_limits: None,
        keep_radius: None,
        min_fit: None,
        dither: None,
    };
}

/// When an accepted re-estimate is swapped in, and how the new controller is designed: the
/// candidate firmware policies of docs/ventilation.md (*Why the re-designed controller loses
/// volume*). Applies to [`Ctrl::Adaptive`] only.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Policy {
    /// The condition at the swap point (the breath boundary as the controller sees it).
    pub when: SwapWhen,
    /// Re-design at the power-up design's regulation speed (its `Design::tau`) instead of the
    /// speed the default design takes from the new model's slow pole.
    pub fixed_speed: bool,
    /// Forgetting shift `k` of the window (`λ = 1 − 2^{−k}` per breath; 2 today).
    pub shift: u8,
    /// Restart the trim at each swap: the next breath programmed for the set volume, the
    /// trim's corrections from there on. The firmware's `Ventilation` has no setter for its
    /// programmed volume, so the bench emulates it: the trim's law is incremental (the next
    /// volume is the last plus half the error), and the bench adds the offset `set − programmed`
    /// at the swap to what the trim programs from then on (the sum within the trim's ±25 %;
    /// the firmware's own bound still applies to its part, which may then bind first).
    pub trim_reset: bool,
    /// Study only (the bench knows when the lung changed, the firmware does not): after a lung
    /// change, swap only estimates whose window holds at least this many breaths of the new
    /// lung (0: no wait; an estimate from before the change is held too).
    pub settle: u32,
}

impl Policy {
    /// Today's: every accepted estimate swapped in, re-designed at its own speed, `k` = 2.
    pub const ALWAYS: Policy = Policy {
        when: SwapWhen::Always,
        fixed_speed: false,
        shift: 2,
        trim_reset: false,
        settle: 0,
    };
}

/// The condition on which an accepted re-estimate is swapped in ([`Policy::when`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SwapWhen {
    /// Always (today).
    Always,
    /// Never: the re-estimates are made, judged and reported, the power-up controller runs
    /// (monitor only).
    Never,
    /// Only while the firmware's volume alarm is raised (`Ventilation::alarm`: 2 breaths in a
    /// row outside ±(4 mL + 15 %)).
    VolumeAlarm,
    /// Only when the last reported breath's tracking RMS (the firmware's `BREATH` figure:
    /// setpoint minus reading over the breath) is above this, slm.
    RmsAbove(f32),
}

impl Cell {
    /// `row`'s breath with `wave` under `ctrl`, 12 breaths, no change, trim on, swaps always.
    pub fn new(row: IsoRow, wave: Shape, ctrl: Ctrl) -> Self {
        Cell {
            row,
            wave,
            ctrl,
            breaths: 12,
            changes: Vec::new(),
            trim: true,
            swap_below_fit: None,
            policy: Policy::ALWAYS,
            breath_plant: BreathPlant::TODAY,
        }
    }
}

/// The lung of `row` behind the exhalation valve of the adult preset (5 cmH₂O/(L/s)), its
/// PEEP valve at `peep` cmH₂O.
pub fn row_lung(row: &IsoRow, peep: f64) -> LungParams {
    LungParams {
        peep,
        ..row.lung(&LungParams::adult())
    }
}

/// The plant of `lung`'s power-up: the default blower, `lung` with its PEEP valve at 0.
pub fn power_up_plant(lung: &LungParams) -> PlantArgs {
    PlantArgs {
        compliance: Some(lung.compliance),
        resistance: Some(lung.resistance),
        peep: Some(0.0),
        valve_resistance: Some(lung.valve_resistance),
        ..PlantArgs::preset(Blower::Default, Outlet::Adult)
    }
}

/// The `VENT` settings of `row` with `wave` and the trim `trim`, through the firmware's own
/// checks ([`ventilation::settings`]): VT, rate, `ti` 1 s (every adult row's), PEEP, default
/// bias flow and rise.
pub fn vent_settings(
    row: &IsoRow,
    wave: Shape,
    trim: bool,
) -> Result<VolumeBreath, ExperimentError> {
    let milli = |v: f64| (v * 1000.0).round() as i32;
    let args = VentArgs {
        vt: milli(row.tidal),
        rate: milli(row.rate),
        ti: Some(milli(row.ti())),
        ie: None,
        wave: Some(wave),
        peep: Some(milli(row.peep)),
        bias: None,
        rise: None,
        trim: Some(trim),
    };
    ventilation::settings(&args, DEFAULT_CONFIG.flow_limit)
        .map_err(|e| ExperimentError::Plant(format!("VENT {e} out of range")))
}

/// The state at the switch-over to run mode after the power-up into a lung, and the
/// baselines' tunings (see the [module docs](self)).
#[derive(Clone, Debug)]
pub struct PowerUp {
    /// Sensor-noise seed.
    pub seed: u64,
    /// The rig at the switch-over (its lung's PEEP valve at 0).
    pub rig: Rig,
    /// The firmware at the switch-over.
    pub switchover: Switchover,
    /// SIMC PI gains from the power-up model.
    pub simc: PidGains,
    /// Ziegler–Nichols tuning of the noise-free plant.
    pub zn: ZnTuning,
}

/// The Ziegler–Nichols tuning of the noise-free default blower into `lung` (PEEP valve at 0,
/// as at power-up).
pub fn zn_for(lung: &LungParams) -> Result<ZnTuning, ExperimentError> {
    tune_zn(&power_up_plant(lung))
}

/// Powers the firmware up into `lung` with sensor-noise seed `seed` (see the [module
/// docs](self)); `zn` is [`zn_for`]`(lung)` (the same for every seed).
pub fn power_up(lung: &LungParams, seed: u64, zn: &ZnTuning) -> Result<PowerUp, ExperimentError> {
    let (rig, _sm, sw) = identify(&power_up_plant(lung), seed)?;
    let fopdt = linearised(&sw.model, &sw.map, sw.duty).ok_or(ExperimentError::Fopdt)?;
    let simc = simc_pi(&fopdt, TS_S).ok_or(ExperimentError::Fopdt)?;
    Ok(PowerUp {
        seed,
        rig,
        switchover: sw,
        simc: simc.gains,
        zn: *zn,
    })
}

/// One breath: the lung's truth and the firmware's figures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Breath {
    /// Breath number, from 1.
    pub number: u32,
    /// Set tidal volume, mL.
    pub set_ml: f64,
    /// Volume the lung gained while the valve was closed, mL (the truth).
    pub delivered_ml: f64,
    /// The firmware's delivered volume (its readings integrated), mL; NaN if not reported.
    pub measured_ml: f64,
    /// The volume the breath was programmed for (set volume and trim), mL; NaN if not
    /// reported.
    pub command_ml: f64,
    /// Largest airway pressure at the blower's outlet over the breath, cmH₂O.
    pub peak_pressure: f64,
    /// Lung pressure at the end of the breath's expiration, cmH₂O.
    pub end_pressure: f64,
    /// Lung pressure when the breath starts (its inspiration's first tick), cmH₂O: breath 1's
    /// is what the firmware's lead-in left.
    pub start_pressure: f64,
    /// Set PEEP, cmH₂O.
    pub peep: f64,
    /// RMS of the true flow minus the program's setpoint (as trimmed) over the breath, slm.
    pub rms: f64,
}

impl Breath {
    /// Delivered minus set volume, percent of the set volume.
    pub fn error_pct(&self) -> f64 {
        100.0 * (self.delivered_ml - self.set_ml) / self.set_ml
    }

    /// Whether the delivered volume is within `±(4 mL + rel · VT)` (`rel` 0.15: ISO
    /// 80601-2-12's band; 0.05 the target).
    pub fn within(&self, rel: f64) -> bool {
        (self.delivered_ml - self.set_ml).abs() <= ventilation::BAND_ML as f64 + rel * self.set_ml
    }

    /// End-expiratory pressure minus the set PEEP, cmH₂O.
    pub fn peep_error(&self) -> f64 {
        self.end_pressure - self.peep
    }
}

/// One cell's run.
#[derive(Clone, Debug)]
pub struct CellRun {
    /// Per breath.
    pub breaths: Vec<Breath>,
    /// The adaptive controller's re-estimates (empty for the others).
    pub estimates: Vec<Estimate>,
    /// The adaptive controller's swaps: the breath (from 1) the new controller took over at
    /// and its design's regulation time constant `Design::tau`, s; the power-up design's first
    /// at breath 0.
    pub designs: Vec<(u32, f32)>,
}

impl CellRun {
    /// Controller swaps (adaptive).
    pub fn swaps(&self) -> usize {
        self.estimates
            .iter()
            .filter(|e| e.swapped_at.is_some())
            .count()
    }
}

/// The controller in the loop.
enum Loop {
    Rst(Box<Running>),
    Pid(Pid, u32),
}

/// Runs `cell` from the switch-over `p` (see the [module docs](self)).
pub fn run_cell(p: &PowerUp, cell: &Cell) -> Result<CellRun, ExperimentError> {
    run_cell_figures(p, cell).map(|(run, _)| run)
}

/// [`run_cell`], and per breath (from 1) the RMS of the true flow minus the program's setpoint
/// over the breath's inspiration only (the valve closed), slm.
pub fn run_cell_figures(p: &PowerUp, cell: &Cell) -> Result<(CellRun, Vec<f64>), ExperimentError> {
    let vb = vent_settings(&cell.row, cell.wave, cell.trim)?;
    let sw = &p.switchover;
    let mut rig = p.rig.clone();
    if let Some(l) = rig.lung.as_mut() {
        l.set_params(LungParams {
            peep: cell.row.peep,
            ..l.params().clone()
        });
    }
    let table = sw.map.table();
    let mut designs = Vec::new();
    let mut ctrl = match cell.ctrl {
        Ctrl::Adaptive | Ctrl::Frozen => {
            let d0 = design(&sw.model).ok_or(ExperimentError::Score)?;
            designs.push((0, d0.tau));
            Loop::Rst(Box::new(Running::new(
                sw.model,
                &d0,
                &table,
                map_slm(&table, sw.duty),
                sw.flow,
            )))
        }
        Ctrl::Simc | Ctrl::Zn => {
            let gains = if cell.ctrl == Ctrl::Simc {
                p.simc
            } else {
                p.zn.gains
            };
            let mut pid = Pid::new(gains, firmware_limits(), TS_S).map_err(ExperimentError::Pid)?;
            pid.start(
                f64::from(sw.duty) / f64::from(DUTY_FULL_SCALE),
                f64::from(sw.flow),
            );
            Loop::Pid(pid, u32::from(sw.baseline_preview))
        }
    };
    let period = u32::from(vb.wave.period());
    let insp = u32::from(vb.wave.inspiration());
    let rules = Rules {
        mode: if cell.ctrl == Ctrl::Adaptive {
            Mode::Adapt
        } else {
            Mode::Frozen
        },
        every: 1,
        method: ridge_core::RidgeM::PAPER,
        units: 1,
        swap_below_fit: cell.swap_below_fit,
        acceptance: ridge_core::reid::Acceptance {
            // One inspiration less its seed when the window takes the inspirations only.
            holdout_min: if cell.breath_plant.feed.inspiration_only {
                insp / 2
            } else {
                period
            },
            model: cell.breath_plant.model_limits.unwrap_or(acceptance().model),
            min_fit: cell.breath_plant.min_fit.unwrap_or(acceptance().min_fit),
            ..acceptance()
        },
    };
    let mut dither = match (cell.breath_plant.dither, &ctrl) {
        (Some(d), Loop::Rst(_)) => Some(DitherGen::new(d, p.seed).ok_or(ExperimentError::Score)?),
        _ => None,
    };
    let mut store: WindowStore = [0; window_len(ridge_core::PARAMS_MAX)];
    let mut reest = match cell.ctrl {
        Ctrl::Adaptive => Some(Reestimation::with_feed(
            &sw.model,
            cell.policy.shift,
            rules,
            &mut store,
            cell.breath_plant.feed,
        )?),
        _ => None,
    };
    let program = Program::Volume(vb);
    let mut sp = Setpoint::new(program, sw.flow);
    let mut vent = Ventilation::new(vb.tidal);
    let mut applied = sw.duty;
    let mut raw = rig.step(sw.duty);
    let mut ended = sw.flow;
    let mut breaths: Vec<Breath> = Vec::new();
    let mut reported: Vec<(u32, f64, f64)> = Vec::new();
    let (mut sq, mut peak, mut volume_at_close) = (0.0, 0.0f64, 0.0);
    // The inspiration's squared tracking errors summed (slm²) and ticks; per breath, its RMS.
    let (mut sq_insp, mut n_insp) = (0.0f64, 0u32);
    let mut insp_rms: Vec<f64> = Vec::new();
    let mut delivered = f64::NAN;
    let mut start_pressure = f64::NAN;
    let fixed_tau = designs
        .first()
        .map(|d| d.1)
        .filter(|_| cell.policy.fixed_speed);
    // The last reported breath's tracking RMS, slm (the policy's `RmsAbove`).
    let mut last_rms = 0.0f32;
    // `Policy::trim_reset`: the offset added to the trim's programmed volume (mL), and the one
    // in force at each breath's start.
    let mut trim_offset = 0.0f32;
    let mut offsets: Vec<(u32, f32)> = Vec::new();
    let span = vb.tidal * f32::from(ventilation::TRIM_PERCENT) / 100.0;
    let lung_of = |rig: &Rig| {
        rig.lung
            .as_ref()
            .map(|l| (l.volume(), l.pressure(), l.airway_pressure()))
    };
    // The breath `number` that has just ended, from its figures: volume the lung gained (mL),
    // peak pressure, pressure at its start (cmH₂O), squared tracking errors summed (slm²).
    let finished = |number: u32, rig: &Rig, delivered_ml: f64, peak: f64, start: f64, sq: f64| {
        let (_, end_pressure, _) = lung_of(rig).unwrap_or_default();
        Breath {
            number,
            set_ml: f64::from(vb.tidal),
            delivered_ml,
            measured_ml: f64::NAN,
            command_ml: f64::NAN,
            peak_pressure: peak,
            end_pressure,
            start_pressure: start,
            peep: f64::from(vb.peep),
            rms: (sq / f64::from(period)).sqrt(),
        }
    };
    // The firmware's lead-in (one expiration before breath 1, `setpoint`'s module docs): its
    // ticks are breath 0, counted nowhere.
    let lead = period - insp;
    for k in 0..lead + cell.breaths * period {
        let kb = k.checked_sub(lead);
        let b = kb.map_or(0, |kb| kb / period + 1);
        let phase = kb.map_or(insp + k, |kb| kb % period);
        // The breath boundary: the last breath's figures (before a change of the lung at this
        // boundary moves its pressure), the re-estimation's boundary.
        if kb.is_some() && phase == 0 {
            if b > 1 {
                breaths.push(finished(b - 1, &rig, delivered, peak, start_pressure, sq));
                insp_rms.push((sq_insp / f64::from(n_insp.max(1))).sqrt());
            }
            (sq, peak) = (0.0, 0.0);
            (sq_insp, n_insp) = (0.0, 0);
            start_pressure = lung_of(&rig).map_or(f64::NAN, |l| l.1);
            offsets.push((b, trim_offset));
            if let Some(r) = reest.as_mut() {
                r.boundary(b - 1);
            }
        }
        for c in cell.changes.iter().filter(|c| c.breath == b) {
            let at = match c.at {
                ChangeAt::Boundary => 0,
                ChangeAt::Mid => insp / 2,
            };
            if phase == at {
                if let Some(l) = rig.lung.as_mut() {
                    l.set_params(c.lung.clone());
                }
            }
        }
        let counts = raw_to_counts(raw);
        let y = f32::from(counts) * SLM_PER_COUNT;
        // The swap at the boundary as the controller sees the program (crate::reid::run).
        if let (Loop::Rst(running), Some(r)) = (&mut ctrl, reest.as_mut()) {
            if (k + running.preview)
                .checked_sub(lead)
                .is_some_and(|j| j % period == 0)
            {
                if let Some((model, i)) = r.take_pending() {
                    // The estimate's window ends with breath `snapshot − 1` (from 1); the last
                    // change up to the breath this swap starts.
                    let snapshot = r.estimates().get(i).map_or(0, |e| e.breath + 1);
                    let settled = cell.policy.settle == 0
                        || cell
                            .changes
                            .iter()
                            .filter(|c| c.breath <= b + 1)
                            .map(|c| c.breath)
                            .max()
                            .is_none_or(|c| snapshot >= c + cell.policy.settle);
                    let allowed = settled
                        && match cell.policy.when {
                            SwapWhen::Always => true,
                            SwapWhen::Never => false,
                            SwapWhen::VolumeAlarm => vent.alarm(),
                            SwapWhen::RmsAbove(x) => last_rms > x,
                        };
                    if !allowed {
                        r.hold(i);
                    } else {
                        match running.swapped_keeping(
                            model,
                            Mode::Adapt,
                            &table,
                            y,
                            fixed_tau,
                            cell.breath_plant.keep_radius,
                        ) {
                            Some((n, tau)) => {
                                **running = n;
                                let at = kb.unwrap_or(0).div_ceil(period);
                                r.swapped(i, Some(at));
                                designs.push((at + 1, tau));
                                if cell.policy.trim_reset && vb.trim {
                                    trim_offset = vb.tidal - vent.command();
                                    sp.set_amplitude(vb.wave.amplitude_for(vb.tidal));
                                }
                            }
                            None => r.swapped(i, None),
                        }
                    }
                }
            }
        }
        // Run mode's tick before the PWM write: the previewed setpoint, the breath phase of the
        // coming interval, the setpoint advanced, the controller's duty.
        let preview = match &ctrl {
            Loop::Rst(r) => r.preview,
            Loop::Pid(_, p) => *p,
        };
        let ahead = sp.ahead(preview) + dither.as_mut().map_or(0.0, |g| g.at(k));
        let (inspiring, vphase) = sp.volume_phase().unwrap_or((false, phase));
        let next = sp.advance();
        let (duty, v_counts) = match &mut ctrl {
            Loop::Rst(r) => r.tick(&table, ahead, y, applied),
            Loop::Pid(pid, _) => {
                let d = fraction_to_duty(pid.step(f64::from(ahead), raw_to_flow(raw)));
                (d, table.at(d))
            }
        };
        applied = duty;
        let valve = if inspiring {
            Valve::Closed
        } else {
            Valve::Open
        };
        if valve != rig.valve {
            let (vol, _, _) = lung_of(&rig).unwrap_or_default();
            match valve {
                Valve::Closed => volume_at_close = vol,
                Valve::Open => delivered = vol - volume_at_close,
            }
        }
        rig.valve = valve;
        let flow = rig.true_flow(duty);
        raw = rig.sensor.measure_raw(flow);
        let (_, _, p_aw) = lung_of(&rig).unwrap_or_default();
        peak = peak.max(p_aw);
        sq += (flow - f64::from(next)).powi(2);
        if inspiring && kb.is_some() {
            sq_insp += (flow - f64::from(next)).powi(2);
            n_insp += 1;
        }
        // After the PWM write: the firmware's breath bookkeeping (with this tick's reading),
        // the re-estimation.
        let mut event = None;
        vent.after_pwm(&mut sp, vphase, counts, ended, &mut event);
        if trim_offset != 0.0 && vphase == insp {
            // The trim moved at the inspiration's end: its volume and the offset.
            let v = (vent.command() + trim_offset).clamp(vb.tidal - span, vb.tidal + span);
            sp.set_amplitude(vb.wave.amplitude_for(v));
        }
        if let Some(Event::Breath(s)) = event {
            reported.push((s.number, f64::from(s.delivered), f64::from(s.command)));
            last_rms = (s.sum_sq / f32::from(s.samples.max(1))).sqrt();
        }
        ended = next;
        if let (Loop::Rst(running), Some(r), Some(_)) = (&ctrl, reest.as_mut(), kb) {
            r.after_pwm_in(v_counts, raw_to_counts(raw), &running.model, inspiring);
        }
    }
    // The next tick's bookkeeping: the last breath's `BREATH` figures.
    let mut event = None;
    let vphase = sp.volume_phase().map_or(0, |(_, p)| p);
    vent.after_pwm(&mut sp, vphase, raw_to_counts(raw), ended, &mut event);
    if let Some(Event::Breath(s)) = event {
        reported.push((s.number, f64::from(s.delivered), f64::from(s.command)));
    }
    breaths.push(finished(
        cell.breaths,
        &rig,
        delivered,
        peak,
        start_pressure,
        sq,
    ));
    insp_rms.push((sq_insp / f64::from(n_insp.max(1))).sqrt());
    for (n, vd, cmd) in reported {
        let offset = offsets.iter().find(|o| o.0 == n).map_or(0.0, |o| o.1);
        if let Some(b) = breaths.iter_mut().find(|b| b.number == n) {
            b.measured_ml = vd;
            b.command_ml = f64::from((cmd as f32 + offset).clamp(vb.tidal - span, vb.tidal + span));
        }
    }
    let run = CellRun {
        breaths,
        estimates: reest.map(Reestimation::into_estimates).unwrap_or_default(),
        designs,
    };
    Ok((run, insp_rms))
}

/// What became of re-estimates: counts by outcome.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Outcomes {
    /// Swapped in.
    pub swapped: usize,
    /// Accepted, the swap rule kept the running model.
    pub held: usize,
    /// Accepted, the design refused the model.
    pub design_refused: usize,
    /// Refused: held-out fit below the minimum or below the running model's.
    pub fit: usize,
    /// Refused: the model check (stability, static gain range).
    pub model: usize,
    /// Refused otherwise (too little excitation, too few held-out samples, the fit failed).
    pub other: usize,
}

/// [`Outcomes`] of `estimates`.
pub fn outcomes<'a>(estimates: impl IntoIterator<Item = &'a Estimate>) -> Outcomes {
    use ridge_core::reid::Rejection;
    let mut o = Outcomes::default();
    for e in estimates {
        o.swapped += usize::from(e.swapped_at.is_some());
        o.held += usize::from(e.held);
        o.design_refused += usize::from(e.design_refused);
        match (&e.model, &e.verdict) {
            (_, Some(Err(Rejection::Fit { .. }))) => o.fit += 1,
            (_, Some(Err(Rejection::Model(_)))) => o.model += 1,
            (_, Some(Err(_))) | (Some(Err(_)), _) => o.other += 1,
            _ => {}
        }
    }
    o
}

/// The figures of one cell over its breaths `from..` (from 1): the worst |volume error|
/// (percent), whether every breath is within `±(4 mL + rel · VT)`, the largest rise of the
/// peak pressure from the breath before (cmH₂O, breaths `from..` against their previous ones,
/// breath 1 excluded) and the largest |PEEP error| (cmH₂O).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Score {
    /// Worst |delivered − set| / set, percent.
    pub worst_pct: f64,
    /// Every scored breath within `±(4 mL + 5 %)`.
    pub pass5: bool,
    /// Every scored breath within `±(4 mL + 15 %)`.
    pub pass15: bool,
    /// Largest peak-pressure rise from the breath before, cmH₂O.
    pub peak_rise: f64,
    /// Largest |end-expiratory pressure − PEEP|, cmH₂O.
    pub peep_err: f64,
    /// Mean tracking RMS, slm.
    pub rms: f64,
}

/// [`Score`] of `run`'s breaths numbered `from` and later.
pub fn score(run: &CellRun, from: u32) -> Score {
    let b: Vec<&Breath> = run.breaths.iter().filter(|b| b.number >= from).collect();
    let mut peak_rise = f64::NEG_INFINITY;
    for w in run.breaths.windows(2) {
        if w[1].number >= from.max(2) {
            peak_rise = peak_rise.max(w[1].peak_pressure - w[0].peak_pressure);
        }
    }
    Score {
        worst_pct: b.iter().map(|b| b.error_pct().abs()).fold(0.0, f64::max),
        pass5: b.iter().all(|b| b.within(0.05)),
        pass15: b.iter().all(|b| b.within(0.15)),
        peak_rise,
        peep_err: b.iter().map(|b| b.peep_error().abs()).fold(0.0, f64::max),
        rms: b.iter().map(|b| b.rms).sum::<f64>() / b.len().max(1) as f64,
    }
}

/// After a lung change in breath `at` (from 1): the breaths from `at` on, counted from 1 at
/// `at`. Per band `rel`, the count of the last breath outside `±(4 mL + rel · VT)` (0: none
/// outside; the "back within the band within 2 breaths" is a count of at most 1).
pub fn last_outside(run: &CellRun, at: u32, rel: f64) -> u32 {
    run.breaths
        .iter()
        .filter(|b| b.number >= at && !b.within(rel))
        .map(|b| b.number - at + 1)
        .max()
        .unwrap_or(0)
}

/// A run against the targets after a lung change in breath `at` (from 1; the
/// change breath counts 1): back within ±(4 mL + 15 %) within 2 breaths, within ±(4 mL + 5 %)
/// within 4, no breath outside ±35 %.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChangeVerdict {
    /// The count of the last breath outside ±(4 mL + 15 %) ([`last_outside`]; 0: none).
    pub last15: u32,
    /// The same for ±(4 mL + 5 %).
    pub last5: u32,
    /// Worst |volume error| from the change breath on, percent.
    pub worst_pct: f64,
    /// Largest peak airway pressure from the change breath on, cmH₂O.
    pub peak_pressure: f64,
}

impl ChangeVerdict {
    /// Back within ±(4 mL + 15 %) from the change's 2nd breath.
    pub fn meets15(&self) -> bool {
        self.last15 <= 1
    }

    /// Back within ±(4 mL + 5 %) from the change's 4th breath.
    pub fn meets5(&self) -> bool {
        self.last5 <= 3
    }

    /// No breath outside ±35 %.
    pub fn meets35(&self) -> bool {
        self.worst_pct <= 35.0
    }
}

/// [`ChangeVerdict`] of `run` for a change in breath `at` (from 1).
pub fn change_verdict(run: &CellRun, at: u32) -> ChangeVerdict {
    let after = || run.breaths.iter().filter(|b| b.number >= at);
    ChangeVerdict {
        last15: last_outside(run, at, 0.15),
        last5: last_outside(run, at, 0.05),
        worst_pct: after().map(|b| b.error_pct().abs()).fold(0.0, f64::max),
        peak_pressure: after().map(|b| b.peak_pressure).fold(0.0, f64::max),
    }
}

/// The breaths a volume-controlled square breath needs to reach its set volume after a change
/// of the lung when the peak airway pressure may rise by at most `rise` cmH₂O a breath (issue
/// 32's "+5 cmH₂O on the previous breath"), on the ideal single-compartment lung: the peak of a
/// square breath of `V` mL over `ti` s is `PEEP + V / C + R · V / (1000 · ti)` (no bias flow,
/// no rise time). Before the change it is that of the set volume `vt`; breath `n` after it
/// (the change breath is 1, changed at its boundary) may deliver at most the volume whose peak
/// is the old peak plus `n · rise`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PressureLimited {
    /// Peak airway pressure of the set volume on the lung before, cmH₂O.
    pub peak_before: f64,
    /// The same on the lung after, cmH₂O.
    pub peak_after: f64,
    /// Volume error of the change breath under the limit, percent.
    pub first_pct: f64,
    /// The breath (change breath = 1) from which the volume is within `±(4 mL + 15 %)`.
    pub within15: u32,
    /// The same for `±(4 mL + 5 %)`.
    pub within5: u32,
}

/// [`PressureLimited`] for the set volume `vt` (mL), inspiration `ti` (s), PEEP `peep`
/// (cmH₂O), the lung `(C, R)` before and after (mL/cmH₂O, cmH₂O/(L/s)) and the allowed rise
/// `rise` (cmH₂O a breath, positive).
pub fn pressure_limited(
    vt: f64,
    ti: f64,
    peep: f64,
    before: (f64, f64),
    after: (f64, f64),
    rise: f64,
) -> PressureLimited {
    // cmH₂O per mL of the square breath.
    let slope = |(c, r): (f64, f64)| 1.0 / c + r / (1000.0 * ti);
    let peak_before = peep + vt * slope(before);
    let peak_after = peep + vt * slope(after);
    let volume = |n: u32| ((peak_before + f64::from(n) * rise - peep) / slope(after)).min(vt);
    let within = |rel: f64| {
        (1..=10_000)
            .find(|&n| vt - volume(n) <= ventilation::BAND_ML as f64 + rel * vt)
            .unwrap_or(u32::MAX)
    };
    PressureLimited {
        peak_before,
        peak_after,
        first_pct: 100.0 * (volume(1) - vt) / vt,
        within15: within(0.15),
        within5: within(0.05),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Row 1's breath (500 mL in 1 s, PEEP 5) from C 50 R 5 to C 10 R 5, by hand: the peak is
    /// 5 + 500 · (1/50 + 5/1000) = 17.5 before and 5 + 500 · 0.105 = 57.5 after; breath `n`
    /// may deliver (12.5 + 5 n) / 0.105 mL: 166.7 (−66.7 %) on the first, 404.8 on the sixth,
    /// 452.4 (≥ 421 mL, the 15 % band) on the seventh, 500 (≥ 471 mL, the 5 % band) on the
    /// eighth.
    #[test]
    fn pressure_limited_by_hand() {
        let p = pressure_limited(500.0, 1.0, 5.0, (50.0, 5.0), (10.0, 5.0), 5.0);
        assert!((p.peak_before - 17.5).abs() < 1e-9);
        assert!((p.peak_after - 57.5).abs() < 1e-9);
        assert!((p.first_pct - (100.0 * (17.5 / 0.105 - 500.0) / 500.0)).abs() < 1e-9);
        assert_eq!((p.within15, p.within5), (7, 8));
        // A change that lowers the peak is within at once.
        let p = pressure_limited(500.0, 1.0, 5.0, (10.0, 5.0), (50.0, 5.0), 5.0);
        assert_eq!((p.first_pct, p.within15, p.within5), (0.0, 1, 1));
    }
}
