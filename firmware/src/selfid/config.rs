//! [`Config`]: the settings of the self-identification state machine and their defaults.

use ridge_core::control::{Limits, ModelLimits, Spec};
use ridge_core::{Grid, Offset, OrderRange, Search};

use crate::excitation::FlowShape;
#[cfg(doc)]
use crate::excitation::FlowSteps;
use crate::monitor::MonitorConfig;
use crate::setpoint::Program;
use crate::tracking::TrackingConfig;
use crate::units::{DUTY_FULL_SCALE, FRACTION_PER_DUTY, TS_S};

/// The no-flow check's fraction of the expected flow, as a right shift: a flow below
/// `expected >> LOSS_SHIFT` (a quarter) is missing (see [`Config::loss_ticks`]). A quarter,
/// not a half: a blower that lost up to 75 % of its gain (a leak upstream of the sensor)
/// still runs, left to the run-mode drift monitor, while a dead pump or PWM line drops to 0;
/// and the linear expectation may overestimate the convex fan curve's flow by up to a
/// factor of about 2 in the identified range (the static gain is a secant).
pub const LOSS_SHIFT: u32 = 2;

/// Settings of the state machine. Duties in 1/10 000 of full scale, flows in SFM3300 counts
/// (1/120 slm), times in ticks of 10 ms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Duty while settling, searching and between attempts (default 3000 = 30 %).
    pub base_duty: u16,
    /// Ticks at the base duty before an identification attempt or before run mode (default
    /// 150 = 1.5 s). The first settle phase after the pump stood still also measures the
    /// plant's lag from its start-up (see [`Records::lag_max`]).
    pub settle_ticks: u16,
    /// The identification's records: the scan that measures the static map, the estimation
    /// and the validation records (see [`Records`]).
    pub records: Records,
    /// Structure search on the estimation record (the map's flow `v` in, the measured flow
    /// out, deviations from the operating point). Default: ridge-core's `Search::DEFAULT`
    /// (Ridge-M γ = 1000, β = 0.01, 200 iterates, delay-free AIC with α = 12, exact pruning)
    /// with an intercept (it takes up what the map's flow at the operating point and the
    /// settled flow leave between them) on the grid p 1..=5, q 1..=6, d 0..=6 (210
    /// candidates). Why not p = 6: on 7 s records an ARX(6, ·) model now and then takes a
    /// large θ₆ (~0.25), a ring of poles at the controller design's keep radius 0.8, which
    /// the design refuses (`FAULT control slow-poles`): 3 of 180 simulated identifications
    /// (9 blower/outlet presets × 20 noise seeds), none of 540 with p ≤ 5, the same fits.
    /// [`ridge_core::Criterion::Validation`] is not supported here.
    pub search: Search<f32>,
    /// Smallest accepted free-run fit on the validation record, percent (default 70).
    pub min_fit: f32,
    /// Smallest RMS deviation of the flow from its mean over the estimation record, slm
    /// (default 1.0): below it the record is "not excited".
    pub min_response: f32,
    /// Largest number of sensor errors bridged within one record (default 10).
    pub max_gaps: u16,
    /// Identification attempts before the fault state (default 3).
    pub attempts: u8,
    /// Consecutive sensor errors that raise a fault (default 5).
    pub sensor_fault_limit: u8,
    /// Largest |flow| accepted, counts (default 30 000 = 250 slm).
    pub flow_limit: i16,
    /// Stall detection: at a duty of at least `stall_duty` (default 4000 = 40 %) ...
    pub stall_duty: u16,
    /// ... a flow below `stall_flow` counts (default 240 = 2 slm) ...
    pub stall_flow: i16,
    /// ... for `stall_ticks` consecutive ticks (default 50 = 0.5 s) is a stall.
    pub stall_ticks: u16,
    /// Frozen sensor: this many identical consecutive readings (default 50 = 0.5 s) ...
    ///
    /// Why an exact repeat is evidence: the SFM3300 resolves 1/120 slm per count, and a
    /// healthy reading of a running blower moves by several counts from one 10 ms sample to the
    /// next (the simulated sensor: 3 % of the reading, at 2 slm σ = 7.6 counts, so two
    /// consecutive readings are equal with probability ≈ 1/(2√π σ) ≈ 0.04). Even if a real
    /// part were 15 times quieter (σ = 0.5 count), two equal readings in a row would have a
    /// probability of at most 0.57, and 50 in a row 0.57⁴⁹ ≈ 1e-12. A sensor frozen at a
    /// plausible flow is therefore flagged after `frozen_ticks` ticks (0.5 s). 0 turns the
    /// check off.
    pub frozen_ticks: u16,
    /// ... at |flow| of at least `frozen_flow` counts (default 240 = 2 slm) is a frozen
    /// sensor. Below it exact repeats are legitimate (a stopped pump reads a constant zero
    /// point); a reading frozen there while the pump is commanded on reads as no flow and is
    /// caught by the stall and no-flow checks. A reading stuck at the sensor's full scale is
    /// beyond [`flow_limit`](Self::flow_limit) and faults at once as out of range.
    pub frozen_flow: i16,
    /// Missing flow response: the flow stays below a quarter of the expected flow (see
    /// [`LOSS_SHIFT`]) for this many
    /// consecutive checked ticks (default 100 = 1 s; ticks where no flow is expected do not
    /// count and do not reset) → `FAULT noflow`. The expected flow at the applied duty `u`:
    /// - after a settle phase, `y0 · u / u0` for `u ≥ u0` (the settled operating point `u0`,
    ///   `y0`; a blower's flow rises at least in proportion to the duty above its operating
    ///   point, as its fan curve is convex and its dead zone above 0), nothing below `u0`;
    /// - in run mode, `y0 + K (u − u0)` at every duty, `K` the identified model's static gain;
    /// - checked only where a quarter of it is at least [`stall_flow`](Self::stall_flow).
    ///
    /// Detection time after the flow is lost: the blower's coast-down below a quarter of
    /// the expected flow plus `loss_ticks` checked ticks (in run mode and while the base duty
    /// is held all ticks are checked; during the records those at or above the base duty).
    /// Nothing is expected before the first settle phase ends, and a dead line from power-up
    /// settles near 0 slm: that case is the stall check's, in the first stretch of the
    /// excitation at [`stall_duty`](Self::stall_duty) or more. The settled flow alone proves
    /// nothing: a stiff test lung gives less than 1 slm at the 30 % base duty. The 1 s covers
    /// healthy transients below a quarter (a duty step down against a filled test lung closes
    /// the blower's check valve for a few hundred milliseconds). 0 turns the check off.
    pub loss_ticks: u16,
    /// Run-mode model monitor (one-step residuals, drift).
    pub monitor: MonitorConfig,
    /// The flow controller.
    pub control: ControlConfig,
    /// Run mode's re-identification while ventilating (on the ATmega2560 only with the
    /// feature `atmega2560-reid`, over its flash budget: docs/boards.md).
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    pub reid: crate::reid::ReidConfig,
}

/// Settings of the flow controller: its design, its limits and what it tracks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlConfig {
    /// The speed knob: time constant of the setpoint response, s; the regulation loop
    /// (disturbances, margin) is designed at the same speed. `None` (the default): the
    /// setpoint response follows a reference model at `ridge_core::control::REFERENCE_S`
    /// (0.08 s) and the regulation loop gets a quarter of the model's open-loop time constant
    /// (see `ridge_core::control::Spec`).
    pub tau: Option<f32>,
    /// Time constant of the observer pole, s (default 0.095: pole 0.9 at 100 Hz).
    pub observer: f32,
    /// Designs before the controller is refused, each 1.5 times slower (default 5).
    pub tries: u8,
    /// Smallest duty the controller commands, 1/10 000 (default 1500 = 15 %: below it the
    /// blowers' dead zones start).
    pub duty_min: u16,
    /// Largest duty the controller commands, 1/10 000 (default 9500 = 95 %).
    pub duty_max: u16,
    /// Largest duty change per tick, 1/10 000 (default 500 = 5 % per 10 ms).
    pub duty_step: u16,
    /// What a model must satisfy before a controller is designed from it (default: poles
    /// within 0.995, static gain from the map's flow to the measured flow 0.5..2 slm/slm:
    /// the map is the steady flow, so the dynamics' gain is about 1; 0.97..1.03 measured on
    /// the simulated blowers and lungs).
    pub model: ModelLimits<f32>,
    /// Lowest and highest mean slope of a model's map over the records' duty range
    /// ([`Records::low`]..[`Records::high`]), slm per unit duty: a stored record whose map
    /// lies outside is refused at boot (default 20..2000, the old limits of a model's static
    /// gain from the duty; the simulated blowers and lungs have 85..260).
    pub map_slope: [f32; 2],
    /// What run mode tracks (default [`Program::Demo`]).
    pub program: Program,
    /// Tracking figures and alarm.
    pub tracking: TrackingConfig,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl ControlConfig {
    /// The design settings these give: ridge-core's defaults at the loop's [`TS_S`] with this
    /// speed knob and observer (the reference model is set after the design, see
    /// [`REFERENCE_POLE`](super::REFERENCE_POLE)).
    // Out of line: smaller ATmega2560 image (measured by trying each function).
    #[inline(never)]
    pub fn spec(&self) -> Spec<f32> {
        Spec {
            tau: self.tau,
            observer: self.observer,
            ..Spec::new(TS_S)
        }
    }

    /// The controller's duty limits as fractions 0..1 of full scale: `duty_min`, `duty_max`
    /// (at most full scale) and `duty_step` per tick, each `× FRACTION_PER_DUTY`.
    #[inline]
    pub fn limits(&self) -> Limits<f32> {
        Limits {
            min: f32::from(self.duty_min) * FRACTION_PER_DUTY,
            max: f32::from(self.duty_max.min(DUTY_FULL_SCALE)) * FRACTION_PER_DUTY,
            max_step: f32::from(self.duty_step) * FRACTION_PER_DUTY,
        }
    }

    /// The defaults (see each field).
    pub const DEFAULT: ControlConfig = ControlConfig {
        tau: None,
        observer: 0.095,
        tries: 5,
        duty_min: 1_500,
        duty_max: 9_500,
        duty_step: 500,
        model: ModelLimits {
            stable_radius: 0.995,
            gain_min: 0.5,
            gain_max: 2.0,
        },
        map_slope: [20.0, 2_000.0],
        program: Program::Demo,
        tracking: TrackingConfig::DEFAULT,
    };
}

/// The identification's records (duties in 1/10 000 of full scale, flows in SFM3300 counts,
/// times in ticks of 10 ms; docs/identification.md says why these and measures them).
///
/// 1. **Lag**: the first settle phase after the pump stood still starts it from rest; its
///    start-up gives the lag `L` (ticks): the mean residence time `N − Σy / y0` of the flow
///    over the settle phase, at least the first responding tick + 1, at most
///    [`lag_max`](Self::lag_max) ([`lag_default`](Self::lag_default) until measured).
/// 2. **Scan**: from the base duty up to [`scan_high`](Self::scan_high), down to
///    [`scan_low`](Self::scan_low) and up to the base duty again at
///    [`scan_rate`](Self::scan_rate) per tick; each reading is credited to the duty `L`
///    ticks before it, rising or falling, and the map is the mean of the two sides at each
///    knot of the grid [`map_first`](Self::map_first) + k · [`map_step`](Self::map_step)
///    (`ridge_core::MapScan`). Then [`lead_in`](Self::lead_in) × `L` ticks at the base duty,
///    so that the estimation record starts from the settled operating point.
/// 3. **Estimation record**: [`samples`](Self::samples) ticks of random steps
///    (`ridge_core::excitation::RandomSteps`) whose levels are uniform in the map's flow
///    between its flow at [`low`](Self::low) (at least [`min_flow`](Self::min_flow)) and at
///    [`high`](Self::high), each driven at the map's inverse, held [`hold_min`](Self::hold_min)
///    to [`hold_max`](Self::hold_max) × `max(L, lag_floor)` ticks.
/// 4. **Validation record**: [`validation`](Self::validation) ticks of the same kind with
///    another seed, after the search.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Records {
    /// Lowest duty of the scan (default 1500 = 15 %: above every blower's stop duty, 12..14 %).
    pub scan_low: u16,
    /// Highest duty of the scan (default 9500 = 95 %, the controller's highest duty).
    pub scan_high: u16,
    /// Duty change per scan tick (default 40 = 0.4 % a tick, 40 %/s: 4.0 s for the default
    /// scan).
    pub scan_rate: u16,
    /// Duty of the map's first knot (default 1500 = 15 %).
    pub map_first: u16,
    /// Duty between the map's knots (default 533: the 16 knots span 15..94.95 %).
    pub map_step: u16,
    /// Lowest duty of the records' levels (default 2000 = 20 %).
    pub low: u16,
    /// Highest duty of the records' levels (default 8500 = 85 %).
    pub high: u16,
    /// Lowest flow of the records' levels, counts (default 240 = 2 slm: with a lung the
    /// lowest duties give almost no flow).
    pub min_flow: i16,
    /// Shortest hold of a level, in lags (default 2).
    pub hold_min: u8,
    /// Longest hold of a level, in lags (default 5).
    pub hold_max: u8,
    /// The smallest lag the holds are measured in, ticks (default 25: with a lung the
    /// start-up overshoots and its residence time says nothing; the lung's own time
    /// constants are 0.1..0.5 s).
    pub lag_floor: u8,
    /// The lag before one was measured (default 25 ticks).
    pub lag_default: u8,
    /// The largest lag taken from a start-up (default 60 ticks).
    pub lag_max: u8,
    /// Ticks at the base duty after the scan, in lags (default 2).
    pub lead_in: u8,
    /// Samples of the estimation record (default 700 = 7 s).
    pub samples: u16,
    /// Samples of the validation record (default 300 = 3 s).
    pub validation: u16,
    /// Seed of the estimation record's generator; the validation record's is its
    /// complement (default 0x2F1B).
    pub seed: u16,
}

impl Records {
    /// The shape of a record of `samples` ticks with generator seed `seed` after a scan that
    /// measured the lag `lag` (ticks): the estimation record has `self.samples` and
    /// `self.seed`, the validation record `self.validation` and `!self.seed`. Host tools
    /// rebuild the device's records with it ([`FlowSteps::new`] on the `MAP` line's map).
    pub fn shape(&self, lag: u8, samples: u16, seed: u16) -> FlowShape {
        let unit = u16::from(lag.max(self.lag_floor));
        FlowShape {
            low: self.low,
            high: self.high,
            min_flow: self.min_flow,
            hold_min: unit.saturating_mul(u16::from(self.hold_min)).max(1),
            hold_max: unit.saturating_mul(u16::from(self.hold_max)).max(1),
            len: u32::from(samples),
            seed,
        }
    }

    /// The defaults (see each field).
    pub const DEFAULT: Records = Records {
        scan_low: 1_500,
        scan_high: 9_500,
        scan_rate: 40,
        map_first: 1_500,
        map_step: 533,
        low: 2_000,
        high: 8_500,
        min_flow: 240,
        hold_min: 2,
        hold_max: 5,
        lag_floor: 25,
        lag_default: 25,
        lag_max: 60,
        lead_in: 2,
        samples: 700,
        validation: 300,
        seed: 0x2F1B,
    };
}

impl Default for Records {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The default settings as a `static`: what the board images run with ([`Defaults`]). (A
/// static costs its bytes of data; building the settings at run time cost the ATmega2560 1 KB
/// of code.)
pub static DEFAULT_CONFIG: Config = Config::DEFAULT;

/// Where a state machine's settings come from: a [`Config`] chosen at run time
/// (`&'static Config`: tests, host tools, the simulator) or one fixed at compile time
/// ([`Defaults`]: the board images).
///
/// Why two: settings known at compile time let the compiler fold each one into the code that
/// reads it and drop the paths they rule out (the ramp and PRBS excitations, the speed knob
/// given by hand, ...). On the ATmega2560 that is 2.5 KB of flash; the state machine's
/// behaviour is the same (`firmware/tests/selfid.rs`, `defaults_behave_as_the_default_config`).
pub trait Settings: Copy + 'static {
    /// The settings.
    fn config(self) -> &'static Config;
}

impl Settings for &'static Config {
    fn config(self) -> &'static Config {
        self
    }
}

/// [`DEFAULT_CONFIG`], fixed at compile time (see [`Settings`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Defaults;

impl Settings for Defaults {
    #[inline(always)]
    fn config(self) -> &'static Config {
        &DEFAULT_CONFIG
    }
}

impl Config {
    /// The defaults (see each field).
    pub const DEFAULT: Config = Config {
        base_duty: 3_000,
        settle_ticks: 150,
        records: Records::DEFAULT,
        search: Search {
            grid: Grid {
                p: OrderRange::new(1, 5),
                ..Grid::PAPER
            },
            offset: Offset::Intercept,
            ..Search::DEFAULT
        },
        min_fit: 70.0,
        min_response: 1.0,
        max_gaps: 10,
        attempts: 3,
        sensor_fault_limit: 5,
        flow_limit: 30_000,
        stall_duty: 4_000,
        stall_flow: 240,
        stall_ticks: 50,
        frozen_ticks: 50,
        frozen_flow: 240,
        loss_ticks: 100,
        monitor: MonitorConfig::DEFAULT,
        control: ControlConfig::DEFAULT,
        #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
        reid: crate::reid::ReidConfig::DEFAULT,
    };

    /// Run mode's re-identification of `running`, from these settings: the search's Ridge-M
    /// (the paper's for another method), the power-up model's checks where they apply (the
    /// controller's model limits, [`min_response`](Self::min_response),
    /// [`min_fit`](Self::min_fit)) with [`reid`](Self::reid)'s input rule, `holdout` ticks held
    /// out (one breath), and its trigger and swap rule.
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    pub fn reidentification(
        &self,
        running: ridge_core::ArxModel<f32>,
        holdout: u32,
    ) -> crate::reid::Reid {
        let (method, accept) = self.reid_rules(holdout);
        crate::reid::Reid::new(method, accept, &self.reid, running)
    }

    /// [`reidentification`](Self::reidentification) built into `reid` (in place: run mode's
    /// start, see [`crate::reid::Reid::reset`]).
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    pub fn reset_reidentification(
        &self,
        reid: &mut crate::reid::Reid,
        running: ridge_core::ArxModel<f32>,
        holdout: u32,
    ) {
        let (method, accept) = self.reid_rules(holdout);
        reid.reset(method, accept, &self.reid, running);
    }

    /// An idle re-identification from these settings until run mode starts one
    /// ([`crate::reid::Reid::dormant`]).
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    pub fn dormant_reidentification(
        &self,
        running: ridge_core::ArxModel<f32>,
    ) -> crate::reid::Reid {
        let (method, accept) = self.reid_rules(0);
        crate::reid::Reid::dormant(method, accept, &self.reid, running)
    }

    /// The re-identification's estimator and checks (see
    /// [`reidentification`](Self::reidentification)), `holdout` ticks held out.
    #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
    fn reid_rules(
        &self,
        holdout: u32,
    ) -> (ridge_core::RidgeM<f32>, ridge_core::reid::Acceptance<f32>) {
        let method = match self.search.method {
            ridge_core::Method::RidgeM(m) => m,
            _ => ridge_core::RidgeM::PAPER,
        };
        let accept = ridge_core::reid::Acceptance {
            model: self.control.model,
            min_response: self.min_response,
            min_input_response: self.reid.min_input_response,
            min_fit: self.min_fit,
            holdout_min: holdout,
        };
        (method, accept)
    }
}

#[cfg(test)]
mod tests {
    use super::DEFAULT_CONFIG;
    use ridge_core::{ArxModel, Offset};

    /// A first-order plant with a delay of one tick in counts, `y_k = 0.8 y_{k−1} +
    /// 0.3 v_{k−2} + 40`, driven by square breaths of the map's flow (10 and 30 slm, 60 ticks a
    /// breath) with a deterministic ±3-count disturbance: `(v, y)` per tick.
    fn samples(ticks: usize) -> Vec<(i16, i16)> {
        let (mut y, mut v1, mut v2, mut seed) = (0.0f64, 0.0f64, 0.0f64, 12_345u32);
        (0..ticks)
            .map(|k| {
                let v = if k % 60 < 30 { 3600.0 } else { 1200.0 };
                seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                let noise = f64::from((seed >> 16) % 7) - 3.0;
                y = 0.8 * y + 0.3 * v2 + 40.0 + noise;
                (v2, v1) = (v1, v);
                (v as i16, y.round() as i16)
            })
            .collect()
    }

    /// The re-identification run mode builds in place (a dormant one, reset at run mode's start:
    /// `Reid::dormant`, `Reid::reset`) reports what one built by value (`Reid::new`) reports on
    /// the same samples, estimate for estimate; the dormant one takes nothing before its reset.
    #[test]
    fn a_reidentification_reset_in_place_reports_as_one_built_by_value() {
        let running = ArxModel::new(&[0.75], &[0.35], 1, Offset::Intercept, 30.0).expect("model");
        let breath = 60;
        let mut by_value = DEFAULT_CONFIG.reidentification(running, breath);
        let mut in_place = DEFAULT_CONFIG.dormant_reidentification(ArxModel::zero());
        let data = samples(40 * 60);
        for (k, &(v, y)) in data.iter().enumerate().take(3 * 60) {
            let boundary = (k % 60 == 0).then_some((k / 60) as u32 + 1);
            assert_eq!(in_place.after_pwm(v, y, boundary, true, false), None);
            assert_eq!(in_place.take_report(), None, "dormant, tick {k}");
        }
        DEFAULT_CONFIG.reset_reidentification(&mut in_place, running, breath);
        let mut reports = 0;
        for (k, &(v, y)) in data.iter().enumerate() {
            let boundary = (k % 60 == 0).then_some((k / 60) as u32 + 1);
            let a = by_value.after_pwm(v, y, boundary, false, false);
            let b = in_place.after_pwm(v, y, boundary, false, false);
            assert_eq!(a, b, "tick {k}");
            let (a, b) = (by_value.take_report(), in_place.take_report());
            assert_eq!(a, b, "tick {k}");
            reports += usize::from(a.is_some());
        }
        // Every other breath a snapshot, the next one held out: a verdict each.
        assert!(reports >= 15, "{reports} reports");
    }
}
