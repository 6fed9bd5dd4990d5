//! The breath-plant study's computations: the candidate models of the breath's plant, the
//! runs they share (power-ups, lung-change and ISO-row cells), and the figures of their
//! re-estimates against the truth.

use pump_sim::reid::{self, design_verdict, Dither, Estimate, Feed};
use pump_sim::vent_bench::{
    power_up, power_up_plant, row1_lung, run_cell_figures, zn_for, BreathPlant, Cell, CellRun,
    Ctrl, Policy, PowerUp, SwapWhen,
};
use pump_sim::{LungParams, Sfm3300, Sfm3300Params};
use ridge_core::control::{DesignError, ModelLimits};
use ridge_core::input_map::MapTable;
use ridge_core::reid::Rejection;

/// A candidate model of the breath's plant: its name in the tables and the adaptive
/// controller's [`BreathPlant`].
#[derive(Clone, Copy, Debug)]
pub struct Candidate {
    /// As the tables print it.
    pub name: &'static str,
    /// The window's ticks and structure, the model check.
    pub plant: BreathPlant,
}

/// The model check without its static-gain range (poles within the firmware's radius only):
/// the closed-valve plant has no steady flow, so no static gain describes it.
pub fn no_gain_check() -> ModelLimits<f32> {
    ModelLimits {
        gain_min: f32::MIN,
        gain_max: f32::MAX,
        ..reid::acceptance().model
    }
}

/// The radius within which the relaxed re-design keeps the model's poles (`Spec::keep_radius`;
/// the firmware's 0.8): the model check's stability radius, so that every pole but the
/// dominant one an accepted model may have is kept in the closed loop, not refused as a second
/// slow pole.
pub const KEEP_RADIUS: f32 = 0.995;

/// The candidates: today's window, then the inspiration only at the power-up structure, with
/// one more output lag, with one more output and input lag (the lung's volume, the flow's
/// integral, in the differenced ARX); with a setpoint dither of ±1 slm (the largest)
/// and ±5 slm (beyond it: does excitation limit the inspiration's window?); then "relaxed": the static-gain check off and the
/// re-design keeping every slow pole but the dominant one ([`KEEP_RADIUS`]); then "any fit":
/// relaxed, and the held-out fit need only beat the running model's (no 70 % floor).
pub fn candidates() -> Vec<Candidate> {
    let insp = |extra_p, extra_q| Feed {
        inspiration_only: true,
        extra_p,
        extra_q,
    };
    let plant = |feed, relaxed: bool| BreathPlant {
        feed,
        model_limits: relaxed.then(no_gain_check),
        keep_radius: relaxed.then_some(KEEP_RADIUS),
        min_fit: None,
        dither: None,
    };
    // With a PRBS dither of ±`amplitude` slm on the setpoint, 4 ticks a bit (the
    // re-identification study's).
    let dithered = |feed, amplitude| BreathPlant {
        dither: Some(Dither { amplitude, hold: 4 }),
        ..plant(feed, false)
    };
    // Relaxed, and an estimate need only predict the held-out data better than the running
    // model.
    let any_fit = |feed| BreathPlant {
        min_fit: Some(f32::MIN),
        ..plant(feed, true)
    };
    vec![
        Candidate {
            name: "every tick, power-up (p, q) (today)",
            plant: BreathPlant::TODAY,
        },
        Candidate {
            name: "inspiration only, (p, q)",
            plant: plant(insp(0, 0), false),
        },
        Candidate {
            name: "inspiration only, (p + 1, q)",
            plant: plant(insp(1, 0), false),
        },
        Candidate {
            name: "inspiration only, (p + 1, q + 1)",
            plant: plant(insp(1, 1), false),
        },
        Candidate {
            name: "inspiration only, (p, q), ±1 slm dither",
            plant: dithered(insp(0, 0), 1.0),
        },
        Candidate {
            name: "inspiration only, (p + 1, q + 1), ±1 slm dither",
            plant: dithered(insp(1, 1), 1.0),
        },
        Candidate {
            name: "inspiration only, (p, q), ±5 slm dither (beyond the issue's ±1)",
            plant: dithered(insp(0, 0), 5.0),
        },
        Candidate {
            name: "every tick, (p, q), relaxed",
            plant: plant(Feed::ALL, true),
        },
        Candidate {
            name: "inspiration only, (p, q), relaxed",
            plant: plant(insp(0, 0), true),
        },
        Candidate {
            name: "inspiration only, (p + 1, q + 1), relaxed",
            plant: plant(insp(1, 1), true),
        },
        Candidate {
            name: "every tick, (p, q), relaxed, any fit",
            plant: any_fit(Feed::ALL),
        },
        Candidate {
            name: "inspiration only, (p, q), relaxed, any fit",
            plant: any_fit(insp(0, 0)),
        },
        Candidate {
            name: "inspiration only, (p + 1, q + 1), relaxed, any fit",
            plant: any_fit(insp(1, 1)),
        },
    ]
}

/// What every table's runs share: the seeds and the sensor of the breaths.
#[derive(Clone, Copy, Debug)]
pub struct Runs {
    /// Noise seeds 1 to `seeds`.
    pub seeds: u64,
    /// The breaths read by a noise-free sensor (its quantisation only), the power-up as
    /// always with the SFM3300 noise model: a diagnosis (is the sensor's noise the limit?).
    pub ideal_sensor: bool,
}

impl Runs {
    /// The power-ups into `lung` with its PEEP valve at 0; failures printed and skipped.
    pub fn power_ups(&self, lung: &LungParams) -> Vec<PowerUp> {
        let first = LungParams {
            peep: 0.0,
            ..lung.clone()
        };
        let zn = match zn_for(&first) {
            Ok(z) => z,
            Err(e) => {
                eprintln!("ZN tuning C {} R {}: {e}", lung.compliance, lung.resistance);
                return Vec::new();
            }
        };
        (1..=self.seeds)
            .filter_map(|seed| {
                power_up(&first, seed, &zn)
                    .map_err(|e| eprintln!("power-up seed {seed}: {e}"))
                    .ok()
            })
            .map(|mut p| {
                if self.ideal_sensor {
                    p.rig.sensor = Sfm3300::new(Sfm3300Params::ideal(), p.seed);
                }
                p
            })
            .collect()
    }
}

/// One run: the cell's run and its per-breath inspiration RMS (slm).
pub type Run = (CellRun, Vec<f64>);

/// `cell` from every power-up; failures printed and skipped.
pub fn runs(ups: &[PowerUp], cell: &Cell) -> Vec<Run> {
    ups.iter()
        .filter_map(|p| {
            run_cell_figures(p, cell)
                .map_err(|e| eprintln!("row {} seed {}: {e}", cell.row.row, p.seed))
                .ok()
        })
        .collect()
}

/// The adaptive controller with `plant`, swapping `when`, re-designed at the power-up design's
/// regulation speed (as the firmware does), trim `trim`; `None`: the frozen power-up design.
pub fn under(cell: Cell, plant: Option<BreathPlant>, when: SwapWhen, trim: bool) -> Cell {
    Cell {
        trim,
        ctrl: if plant.is_some() {
            Ctrl::Adaptive
        } else {
            Ctrl::Frozen
        },
        policy: Policy {
            when,
            fixed_speed: true,
            ..Policy::ALWAYS
        },
        breath_plant: plant.unwrap_or(BreathPlant::TODAY),
        ..cell
    }
}

/// Row 1's breath's truth on the lung `(C, R)` through `table`: the closed-valve step from the
/// 5 slm bias flow with the duty of 35 slm held (row 1's square inspiration), 100 ticks, slm
/// per slm of the map.
pub fn closed_truth(table: &MapTable, (c, r): (f64, f64)) -> Vec<f64> {
    let l = row1_lung(c, r);
    let plant = power_up_plant(&l);
    reid::through_map(&reid::closed_valve_step(&plant, &l, 5.0, 35.0, 100), table).step
}

/// What became of one re-estimate, by the checks' order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// No model (refused by the fit) or the run ended first.
    NoModel,
    /// Refused: too little excitation or too few held-out samples.
    Other,
    /// Refused by the model check: unstable or not finite.
    Unstable,
    /// Refused by the model check's static-gain range.
    Gain,
    /// Refused on the held-out data.
    Fit,
    /// Accepted.
    Accepted,
}

/// The figures of one re-estimate.
#[derive(Clone, Copy, Debug)]
pub struct Figures {
    /// What became of it.
    pub outcome: Outcome,
    /// The model's unit step response after 50 and 100 ticks, slm per slm of the map; NaN
    /// without a model.
    pub step: (f64, f64),
    /// The model's static gain; NaN without a model.
    pub gain: f64,
    /// Held-out free-run fits, estimate and running model, percent (when scored).
    pub fit: Option<(f64, f64)>,
    /// The window's input (`v`) RMS about its mean, slm.
    pub v_rms: f64,
    /// The design at the power-up design's speed: `Ok` or why it refused (without a model:
    /// `None`).
    pub design: Option<Result<(), DesignError<f32>>>,
    /// The same keeping the model's poles within [`KEEP_RADIUS`].
    pub design_kept: Option<Result<(), DesignError<f32>>>,
}

/// The figures of `e`, the design tried at `tau` (s).
pub fn figures(e: &Estimate, tau: f32) -> Figures {
    let model = e.model.and_then(Result::ok);
    let step = model.map_or((f64::NAN, f64::NAN), |m| {
        let s = reid::model_step(&m, 100);
        (s[49], s[99])
    });
    let (outcome, fit) = match (&model, &e.verdict) {
        (None, _) | (_, None) => (Outcome::NoModel, None),
        (_, Some(Ok((c, r)))) => (Outcome::Accepted, Some((f64::from(*c), f64::from(*r)))),
        (_, Some(Err(Rejection::Fit { candidate, running }))) => (
            Outcome::Fit,
            Some((f64::from(*candidate), f64::from(*running))),
        ),
        (_, Some(Err(Rejection::Model(ridge_core::control::ModelFault::Gain { .. })))) => {
            (Outcome::Gain, None)
        }
        (_, Some(Err(Rejection::Model(_)))) => (Outcome::Unstable, None),
        (_, Some(Err(_))) => (Outcome::Other, None),
    };
    Figures {
        outcome,
        step,
        gain: model.map_or(f64::NAN, |m| f64::from(m.static_gain())),
        fit,
        v_rms: f64::from(e.input_response),
        design: model.map(|m| design_verdict(&m, tau, None).map(|_| ())),
        design_kept: model.map(|m| design_verdict(&m, tau, Some(KEEP_RADIUS)).map(|_| ())),
    }
}

/// The name of a design verdict, in the firmware's `why=` words.
pub fn why(v: &Result<(), DesignError<f32>>) -> &'static str {
    match v {
        Ok(()) => "ok",
        Err(DesignError::Spec) => "spec",
        Err(DesignError::Singular) => "singular",
        Err(DesignError::SlowPoles) => "slow-poles",
        Err(DesignError::Poles) => "poles",
        Err(DesignError::Margin { .. }) => "margin",
    }
}
