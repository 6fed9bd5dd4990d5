//! The comparison over seeds and plants: [`run_plant`] runs one plant for several noise
//! seeds and summarises each controller ([`Summary`]); [`markdown`] renders the tunings, the
//! comparison, the noisy-run figures and the check of the targets (what `control-table
//! --markdown` prints).
//!
//! # Which run each figure comes from
//! - **Step shape** (rise time, overshoot, settling time): the noise-free replay
//!   ([`CaseRun::clean`]). With the sensor's noise in the loop the true flow itself jitters
//!   (its standard deviation over the end of a level reaches about 1 slm under the RST and
//!   3 slm under the ZN PID), so the last excursion out of a ±1 slm band happens at a random
//!   time near the end of the level and the noisy settling time measures the noise, not the
//!   response; the noisy overshoot and settling time are given separately.
//! - **Everything else** (steady-state error, IAE, breath RMS, duty total variation): the runs
//!   with the sensor's noise ([`CaseRun::traces`]), from the true flow; the IAE and breath RMS
//!   from the measured flow are given separately.
//!
//! Means are over the four steps of the demo program and the seeds; maxima over the same.

use std::fmt::Write as _;

use ridge_pump_firmware::selfid::Config;
use ridge_pump_firmware::setpoint::DEMO_BREATH;

use super::experiment::{
    run_case_with, score, tune_zn, CaseRun, Controller, ExperimentError, Scores,
};
use super::experiment::{ZnTuning, EXPERIMENT_CONFIG, ZN_SEARCH};
use super::metrics::{mean_present, StepMetrics, SS_WINDOW_S};
use super::simc::{Fopdt, Simc};
use crate::{Blower, Outlet, PlantArgs, Sfm3300Params};

/// The cases a table runs, as command-line options (`control-table`, `step-optimum`): one
/// plant or every preset, and the seeds.
#[derive(Clone, Debug, clap::Args)]
pub struct Cases {
    /// The plant of a single case (ignored with `--all`).
    #[command(flatten)]
    pub plant: PlantArgs,
    /// Every blower preset × every outlet preset (default, small, sluggish × open, adult,
    /// stiff).
    #[arg(long, conflicts_with_all = ["plant", "lung", "compliance", "resistance", "peep", "valve_resistance"])]
    pub all: bool,
    /// Sensor-noise seeds 1..=N; figures are means over them.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
}

impl Cases {
    /// The plants: every preset in the tables' order with `--all`, else the one given.
    pub fn plants(&self) -> Vec<PlantArgs> {
        if self.all {
            Blower::ALL
                .iter()
                .flat_map(|&b| Outlet::ALL.iter().map(move |&o| PlantArgs::preset(b, o)))
                .collect()
        } else {
            vec![self.plant.clone()]
        }
    }

    /// The seeds, 1..=N.
    pub fn seeds(&self) -> Vec<u64> {
        (1..=self.seeds).collect()
    }
}

/// One controller on one plant, over the seeds. Flows in slm, times in s.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// The controller.
    pub controller: Controller,
    /// Mean 10–90 % rise time (noise-free), `None` when no step reached 90 %.
    pub rise_s: Option<f64>,
    /// Mean overshoot (noise-free), percent of the step.
    pub overshoot_pct: f64,
    /// Largest overshoot (noise-free), percent of the step.
    pub overshoot_max_pct: f64,
    /// Largest overshoot with the sensor's noise, percent of the step.
    pub overshoot_noisy_max_pct: f64,
    /// Mean settling time of the steps that settled (noise-free).
    pub settling_s: Option<f64>,
    /// Steps (of 4 × seeds) that did not settle (noise-free).
    pub unsettled: usize,
    /// Mean settling time with the sensor's noise, of the steps that settled.
    pub settling_noisy_s: Option<f64>,
    /// Mean |steady-state error| (mean of `r − y` over the last 0.5 s of a level), slm.
    pub ss_abs: f64,
    /// Largest |steady-state error| / sensor noise σ at the level.
    pub ss_ratio_max: f64,
    /// Mean IAE per step, slm·s.
    pub iae: f64,
    /// Largest IAE of a step, slm·s.
    pub iae_max: f64,
    /// Mean IAE per step from the measured flow, slm·s.
    pub iae_measured: f64,
    /// Mean IAE per step of the noise-free replay, slm·s.
    pub iae_clean: f64,
    /// Mean RMS tracking error over the scored breaths, slm.
    pub breath_rms: f64,
    /// The same from the measured flow, slm.
    pub breath_rms_measured: f64,
    /// Mean duty total variation, percent of full scale per second.
    pub duty_tv_pct: f64,
}

/// One plant over the seeds: the tunings and one [`Summary`] per controller.
#[derive(Clone, Debug)]
pub struct PlantSummary {
    /// The plant.
    pub plant: PlantArgs,
    /// The seeds run.
    pub seeds: Vec<u64>,
    /// Ziegler–Nichols tuning (the same for every seed: the plant is noise-free).
    pub zn: ZnTuning,
    /// FOPDT fit of each seed's identified model.
    pub fopdt: Vec<Fopdt>,
    /// SIMC tuning of each seed.
    pub simc: Vec<Simc>,
    /// Identified structure `(p, q, d)` of each seed.
    pub structures: Vec<(u8, u8, u8)>,
    /// Setpoint preview of each seed, ticks: the RST's and the baselines'.
    pub previews: Vec<(u8, u8)>,
    /// The `CTRL` line of each seed.
    pub ctrl: Vec<String>,
    /// The flow at each seed's switch-over, slm: where its program starts.
    pub starts: Vec<f64>,
    /// In the order of [`Controller::ALL`].
    pub rows: [Summary; 3],
}

/// Sensor noise σ (slm) at a flow of `flow` slm, the default SFM3300 model.
fn noise_sigma(flow: f64) -> f64 {
    Sfm3300Params::default().noise_std(flow)
}

/// The quality targets, as the tables check them: step IAE at most this fraction of
/// the ZN PID's ...
pub const IAE_RATIO_TARGET: f64 = 0.5;
/// ... largest step overshoot, percent of the step ...
pub const OVERSHOOT_TARGET_PCT: f64 = 10.0;
/// ... breath RMS tracking error with a lung, percent of the breath's peak flow
/// ([`breath_pct`]) ...
pub const BREATH_TARGET_PCT: f64 = 5.0;
/// ... and the largest |steady-state error| at most this many sensor noise σ.
pub const SS_RATIO_TARGET: f64 = 1.0;

/// A breath RMS tracking error of `rms` slm as percent of the demo breath's peak flow.
pub fn breath_pct(rms: f64) -> f64 {
    100.0 * rms / f64::from(DEMO_BREATH.peak)
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn max(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(f64::NEG_INFINITY, f64::max)
}

/// The summary of controller `c` over `runs` (one per seed); `None` when a trace cannot be
/// scored.
pub fn summarise(runs: &[CaseRun], c: Controller) -> Option<Summary> {
    let mut clean = Vec::new();
    let mut noisy = Vec::new();
    let mut measured = Vec::new();
    for r in runs {
        // Each controller is scored on the windows of its own preview.
        let p = u32::from(match c {
            Controller::Rst => r.switchover.preview,
            _ => r.switchover.baseline_preview,
        });
        clean.push(score(r.clean_trace(c), false, p)?);
        noisy.push(score(r.trace(c), false, p)?);
        measured.push(score(r.trace(c), true, p)?);
    }
    let steps = |s: &[Scores]| -> Vec<_> {
        s.iter()
            .flat_map(|x| x.steps.iter().zip(&x.levels).map(|(m, &l)| (*m, l)))
            .filter_map(|(m, l)| m.map(|m| (m, l)))
            .collect()
    };
    let (cs, ns, ms) = (steps(&clean), steps(&noisy), steps(&measured));
    let iae = |v: &[(StepMetrics, f64)]| mean(&v.iter().map(|m| m.0.iae).collect::<Vec<_>>());
    Some(Summary {
        controller: c,
        rise_s: mean_present(cs.iter().map(|m| m.0.rise_s)),
        overshoot_pct: mean(&cs.iter().map(|m| m.0.overshoot_pct).collect::<Vec<_>>()),
        overshoot_max_pct: max(cs.iter().map(|m| m.0.overshoot_pct)),
        overshoot_noisy_max_pct: max(ns.iter().map(|m| m.0.overshoot_pct)),
        settling_s: mean_present(cs.iter().map(|m| m.0.settling_s)),
        unsettled: cs.iter().filter(|m| m.0.settling_s.is_none()).count(),
        settling_noisy_s: mean_present(ns.iter().map(|m| m.0.settling_s)),
        ss_abs: mean(&ns.iter().map(|m| m.0.ss_error.abs()).collect::<Vec<_>>()),
        ss_ratio_max: max(ns.iter().map(|m| m.0.ss_error.abs() / noise_sigma(m.1))),
        iae: iae(&ns),
        iae_max: max(ns.iter().map(|m| m.0.iae)),
        iae_measured: iae(&ms),
        iae_clean: iae(&cs),
        breath_rms: mean(&noisy.iter().map(|s| s.breath_rms).collect::<Vec<_>>()),
        breath_rms_measured: mean(&measured.iter().map(|s| s.breath_rms).collect::<Vec<_>>()),
        duty_tv_pct: 100.0 * mean(&noisy.iter().map(|s| s.duty_tv).collect::<Vec<_>>()),
    })
}

/// Runs `plant` for every seed in `seeds` (ZN tuning once, then
/// [`run_case`](super::run_case) per seed) and summarises it.
pub fn run_plant(plant: &PlantArgs, seeds: &[u64]) -> Result<PlantSummary, ExperimentError> {
    run_plant_with(plant, seeds, &EXPERIMENT_CONFIG)
}

/// [`run_plant`] with the firmware's settings `config` instead of [`EXPERIMENT_CONFIG`].
pub fn run_plant_with(
    plant: &PlantArgs,
    seeds: &[u64],
    config: &'static Config,
) -> Result<PlantSummary, ExperimentError> {
    let zn = tune_zn(plant)?;
    let runs = seeds
        .iter()
        .map(|&s| run_case_with(plant, s, &zn, config))
        .collect::<Result<Vec<_>, _>>()?;
    let row = |c| summarise(&runs, c).ok_or(ExperimentError::Score);
    let rows = [
        row(Controller::Rst)?,
        row(Controller::ZnPid)?,
        row(Controller::SimcPi)?,
    ];
    Ok(PlantSummary {
        plant: plant.clone(),
        seeds: seeds.to_vec(),
        zn,
        fopdt: runs.iter().map(|r| r.fopdt).collect(),
        simc: runs.iter().map(|r| r.simc).collect(),
        structures: runs
            .iter()
            .map(|r| {
                let s = r.switchover.model.structure();
                (s.p, s.q, s.d)
            })
            .collect(),
        previews: runs
            .iter()
            .map(|r| (r.switchover.preview, r.switchover.baseline_preview))
            .collect(),
        ctrl: runs
            .iter()
            .map(|r| r.switchover.events.last().cloned().unwrap_or_default())
            .collect(),
        starts: runs.iter().map(|r| f64::from(r.switchover.flow)).collect(),
        rows,
    })
}

/// The lung column: the preset's name, or its parameters when overridden.
pub fn lung_label(p: &PlantArgs) -> String {
    let overridden = p.compliance.is_some()
        || p.resistance.is_some()
        || p.peep.is_some()
        || p.valve_resistance.is_some();
    match (overridden, p.lung()) {
        (true, Ok(Some(l))) => format!(
            "C {} R {} PEEP {} Rv {}",
            l.compliance, l.resistance, l.peep, l.valve_resistance
        ),
        _ => p.lung.name().to_owned(),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_owned(), |x| format!("{x:.digits$}"))
}

fn mean_of(v: impl Iterator<Item = f64>) -> f64 {
    mean(&v.collect::<Vec<_>>())
}

/// RST IAE / ZN PID IAE of a plant.
pub fn iae_ratio(p: &PlantSummary) -> f64 {
    p.rows[Controller::Rst.index()].iae / p.rows[Controller::ZnPid.index()].iae
}

/// The markdown report: tunings, comparison, noisy-run and measured-flow figures, targets.
/// `command` is the command line that produced it.
pub fn markdown(plants: &[PlantSummary], command: &str) -> String {
    let mut o = String::new();
    let seeds = plants
        .first()
        .map(|p| {
            p.seeds
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        })
        .unwrap_or_default();
    let _ = writeln!(o, "Produced by `{command}` (sensor-noise seeds {seeds}).\n");
    let _ = writeln!(o, "### Tunings\n");
    let _ = writeln!(
        o,
        "K_u, T_u: proportional loop on the noise-free plant around {} slm (bisection on the gain \
         between decaying and growing oscillation); relay: ±{} % duty, K_u = 4h/(πa) (cross-check). \
         FOPDT and SIMC: mean over the seeds of the fit of each seed's identified model; \
         θ_e = θ + Ts/2, τ_c = θ_e. Gains in % duty per slm.\n",
        ZN_SEARCH.flow_slm,
        100.0 * super::experiment::RELAY_H
    );
    let _ = writeln!(
        o,
        "| plant | lung | u₀ (%) | K_u (%/slm) | T_u (s) | relay K_u / T_u | ZN K_p / T_i / T_d | \
         model (p,q,d) | K (slm/duty) | τ (s) | θ (s) | SIMC K_c / T_i | preview RST/PIDs (ticks) |"
    );
    let _ = writeln!(
        o,
        "|---|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---|"
    );
    for p in plants {
        let u = &p.zn.ultimate;
        let relay = p.zn.relay.map_or_else(
            || "—".to_owned(),
            |r| format!("{:.2} / {:.3}", 100.0 * r.ku, r.tu_s),
        );
        let g = &p.zn.gains;
        let structures = p
            .structures
            .iter()
            .map(|(a, b, c)| format!("({a},{b},{c})"))
            .collect::<Vec<_>>()
            .join(" ");
        let previews = p
            .previews
            .iter()
            .map(|(rst, pid)| format!("{rst}/{pid}"))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            o,
            "| {} | {} | {:.1} | {:.2} | {:.3} | {} | {:.2} / {:.3} / {:.4} | {} | {:.0} | {:.3} | {:.3} | {:.2} / {:.3} | {} |",
            p.plant.plant.name(),
            lung_label(&p.plant),
            100.0 * u.u0,
            100.0 * u.ku,
            u.tu_s,
            relay,
            100.0 * g.kp,
            g.ti_s,
            g.td_s,
            structures,
            mean_of(p.fopdt.iter().map(|f| f.k)),
            mean_of(p.fopdt.iter().map(|f| f.tau_s)),
            mean_of(p.fopdt.iter().map(|f| f.theta_s)),
            100.0 * mean_of(p.simc.iter().map(|s| s.gains.kp)),
            mean_of(p.simc.iter().map(|s| s.gains.ti_s)),
            previews
        );
    }
    let _ = writeln!(o, "\n### Comparison\n");
    let _ = writeln!(
        o,
        "Rise (10–90 %), overshoot and settling (±2 % of the final value or ±1 slm, whichever is \
         larger): noise-free replay. Steady-state error (mean of r − y over the last {SS_WINDOW_S} s \
         of a level; σ = sensor noise at the level), IAE per step, breath RMS (breaths 2–6, peak \
         {} slm) and duty total variation: runs with sensor noise, true flow. Means over the 4 \
         steps and the seeds; \"max\" over the same.\n",
        DEMO_BREATH.peak
    );
    let _ = writeln!(
        o,
        "| plant | lung | controller | rise (s) | overshoot mean / max (%) | settling (s) | \
         \\|e_ss\\| (slm) | max \\|e_ss\\|/σ | IAE (slm·s) | IAE / ZN | breath RMS (slm) | \
         breath (% peak) | duty TV (%/s) |"
    );
    let _ = writeln!(
        o,
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for p in plants {
        let zn_iae = p.rows[Controller::ZnPid.index()].iae;
        for r in &p.rows {
            let unsettled = if r.unsettled > 0 {
                format!(" ({} unsettled)", r.unsettled)
            } else {
                String::new()
            };
            let _ = writeln!(
                o,
                "| {} | {} | {} | {} | {:.1} / {:.1} | {}{} | {:.2} | {:.2} | {:.3} | {:.2} | {:.2} | {:.1} | {:.0} |",
                p.plant.plant.name(),
                lung_label(&p.plant),
                r.controller.name(),
                opt(r.rise_s, 3),
                r.overshoot_pct,
                r.overshoot_max_pct,
                opt(r.settling_s, 2),
                unsettled,
                r.ss_abs,
                r.ss_ratio_max,
                r.iae,
                r.iae / zn_iae,
                r.breath_rms,
                breath_pct(r.breath_rms),
                r.duty_tv_pct
            );
        }
    }
    let _ = writeln!(
        o,
        "\n### With the noise in the step shape, and from the measured flow\n"
    );
    let _ = writeln!(
        o,
        "| plant | lung | controller | overshoot max, noisy (%) | settling, noisy (s) | \
         IAE noise-free (slm·s) | IAE measured (slm·s) | breath RMS measured (slm) |"
    );
    let _ = writeln!(o, "|---|---|---|---:|---:|---:|---:|---:|");
    for p in plants {
        for r in &p.rows {
            let _ = writeln!(
                o,
                "| {} | {} | {} | {:.1} | {} | {:.3} | {:.3} | {:.2} |",
                p.plant.plant.name(),
                lung_label(&p.plant),
                r.controller.name(),
                r.overshoot_noisy_max_pct,
                opt(r.settling_noisy_s, 2),
                r.iae_clean,
                r.iae_measured,
                r.breath_rms_measured
            );
        }
    }
    let _ = writeln!(o, "\n### Targets (RST designed on the device)\n");
    targets(&mut o, plants);
    o
}

/// The target checks, one bullet each with every miss named.
fn targets(o: &mut String, plants: &[PlantSummary]) {
    let name = |p: &PlantSummary| format!("{}/{}", p.plant.plant.name(), lung_label(&p.plant));
    let rst = |p: &PlantSummary| p.rows[Controller::Rst.index()].clone();
    let mut bullet = |title: &str, limit: &str, vals: Vec<(String, f64, bool)>| {
        let met = vals.iter().filter(|v| v.2).count();
        let misses: Vec<String> = vals
            .iter()
            .filter(|v| !v.2)
            .map(|v| format!("{} {:.2}", v.0, v.1))
            .collect();
        let worst = vals.iter().map(|v| v.1).fold(f64::NEG_INFINITY, f64::max);
        let _ = write!(
            o,
            "- {title} ({limit}): met on {met} of {} (worst {worst:.2})",
            vals.len()
        );
        if misses.is_empty() {
            let _ = writeln!(o, ".");
        } else {
            let _ = writeln!(o, "; missed on {}.", misses.join(", "));
        }
    };
    bullet(
        "Step IAE of the RST / ZN PID's",
        &format!("≤ {IAE_RATIO_TARGET:.2}"),
        plants
            .iter()
            .map(|p| (name(p), iae_ratio(p), iae_ratio(p) <= IAE_RATIO_TARGET))
            .collect(),
    );
    bullet(
        "RST largest overshoot, noise-free, %",
        &format!("≤ {OVERSHOOT_TARGET_PCT}"),
        plants
            .iter()
            .map(|p| {
                (
                    name(p),
                    rst(p).overshoot_max_pct,
                    rst(p).overshoot_max_pct <= OVERSHOOT_TARGET_PCT,
                )
            })
            .collect(),
    );
    bullet(
        "RST largest overshoot with sensor noise, %",
        &format!("≤ {OVERSHOOT_TARGET_PCT}"),
        plants
            .iter()
            .map(|p| {
                let v = rst(p).overshoot_noisy_max_pct;
                (name(p), v, v <= OVERSHOOT_TARGET_PCT)
            })
            .collect(),
    );
    bullet(
        "RST breath RMS with a lung, % of peak",
        &format!("≤ {BREATH_TARGET_PCT}"),
        plants
            .iter()
            .filter(|p| p.plant.has_lung())
            .map(|p| {
                let v = breath_pct(rst(p).breath_rms);
                (name(p), v, v <= BREATH_TARGET_PCT)
            })
            .collect(),
    );
    bullet(
        "RST largest |steady-state error| / sensor noise σ",
        &format!("≤ {SS_RATIO_TARGET}"),
        plants
            .iter()
            .map(|p| {
                let v = rst(p).ss_ratio_max;
                (name(p), v, v <= SS_RATIO_TARGET)
            })
            .collect(),
    );
    let _ = writeln!(
        o,
        "\nσ at the levels 40/25/60/35 slm: {}. The sensor's +0.1 slm zero offset is in every \
         controller's steady state (they all regulate the reading).",
        [40.0, 25.0, 60.0, 35.0]
            .iter()
            .map(|&l| format!("{:.2}", noise_sigma(l)))
            .collect::<Vec<_>>()
            .join(" / ")
    );
}

/// A plain-text line per controller (what `control-table` prints without `--markdown`).
pub fn plain(plants: &[PlantSummary]) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{:<9} {:<6} {:<13} {:>7} {:>7} {:>7} {:>7} {:>6} {:>7} {:>7} {:>6} {:>6}",
        "plant",
        "lung",
        "controller",
        "rise_s",
        "os_max",
        "settle",
        "ss_abs",
        "ss/σ",
        "IAE",
        "IAE/ZN",
        "brRMS",
        "TV%/s"
    );
    for p in plants {
        let zn = p.rows[Controller::ZnPid.index()].iae;
        for r in &p.rows {
            let _ = writeln!(
                o,
                "{:<9} {:<6} {:<13} {:>7} {:>7.1} {:>7} {:>7.2} {:>6.2} {:>7.3} {:>7.2} {:>6.2} {:>6.0}",
                p.plant.plant.name(),
                lung_label(&p.plant),
                r.controller.name(),
                opt(r.rise_s, 3),
                r.overshoot_max_pct,
                opt(r.settling_s, 2),
                r.ss_abs,
                r.ss_ratio_max,
                r.iae,
                r.iae / zn,
                r.breath_rms,
                r.duty_tv_pct
            );
        }
    }
    o
}
