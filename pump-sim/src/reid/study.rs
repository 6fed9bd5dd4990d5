//! One closed-loop run of the re-identification study ([`run`], settings [`Study`]): power-up as
//! the firmware, then square breaths with sudden lung changes, the per-breath figures
//! ([`BreathFigures`]) and every re-estimate; and the figures the study's tables are built from
//! ([`mean_sd`], [`models_in`], [`breaths_in`]).

use ridge_core::reid::{window_len, Acceptance};
use ridge_core::{ArxModel, RidgeM};
use ridge_pump_firmware::reid::ReidConfig;
use ridge_pump_firmware::setpoint::{self, BreathWave, Program, DEMO_BREATH};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::SLM_PER_COUNT;

use super::{design, map_slm, Estimate, Mode, Reestimation, Rules, Running, WindowStore};
use crate::baseline::experiment::{identify, ExperimentError, Switchover, EXPERIMENT_CONFIG};
use crate::{LungParams, PlantArgs, Sfm3300, Sfm3300Params, TS_S};

/// mL per slm·tick: `1000 mL/L / 60 s/min · TS_S`.
const ML_PER_SLM_TICK: f64 = 1000.0 / 60.0 * TS_S;
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
    /// [`Refit`](ridge_core::reid::Refit) units run per tick (the device: 1, see
    /// docs/control.md for their cost).
    pub units: u32,
    /// The setpoint program ([`PROGRAM`]: square breaths).
    pub program: Program,
    /// The swap rule ([`swap_allowed`](super::swap_allowed)): an accepted re-estimate replaces
    /// the running model only when the running model's own held-out free-run fit is below
    /// this, percent; `None` (or 100): always.
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
/// The PRBS bits of a dither (also the ventilation benchmark's, `vent_bench::BreathPlant`).
pub(crate) struct DitherGen {
    d: Dither,
    lfsr: ridge_core::excitation::Lfsr,
    bit: bool,
}

impl DitherGen {
    /// The dither `d`, its LFSR seeded from `seed`; `None` for a seed the LFSR refuses.
    pub(crate) fn new(d: Dither, seed: u64) -> Option<Self> {
        Some(DitherGen {
            d,
            lfsr: ridge_core::excitation::Lfsr::new(7, (seed as u16) | 1)?,
            bit: false,
        })
    }

    /// The dither at tick `k` (a new bit every `hold` ticks), slm.
    pub(crate) fn at(&mut self, k: u32) -> f32 {
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
