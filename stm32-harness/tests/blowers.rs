//! Identification and flow control on the three simulated blowers, with the bounds of the
//! ATmega2560's runs in simavr (`simavr-harness/tests/simavr.rs`: `*_pump_identifies`,
//! `tracks_*`), on the STM32F411 release image:
//!
//! - identification (default blower in `image.rs`; small and sluggish here, open outlet):
//!   `ACCEPT`, no fault, no reset; the firmware's model equal to ridge-core's search rerun on
//!   the host from the samples the sensor served (same structure, coefficients within
//!   [`COEF_TOL`]); its free-run fit on a fresh validation signal (a record the firmware
//!   neither estimates nor validates on, new noise, the loop's timing) ≥ [`MIN_FRESH_FIT`] %;
//!   every control tick within [`TICK_BUDGET`] instructions;
//! - flow control (default, small, sluggish blower × adult and stiff test lung): the design
//!   accepted within [`DESIGN_BUDGET_S`], the demo program (steps, then breaths) run; the
//!   `TRACK` lines equal to the figures recomputed from the served frames; every run-mode
//!   control tick within [`TICK_BUDGET`] instructions; the true flow (scored by `pump_sim`'s
//!   metrics) reaching each level within the sensor noise, with the overshoot and the breath
//!   RMS within the targets (10 %, 5 % of peak) or, where the design is known to miss
//!   them (stiff lung), the simavr tests' regression bounds.

mod common;

use common::elf;
use harness_kit::host::{coefficient_error, host_search};
use harness_kit::validation::{score, FreshRecord};
use pump_sim::baseline::table::breath_pct;
use pump_sim::PumpParams;
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::selfid::Config;
use stm32_harness::bench::secs;
use stm32_harness::session::{self, Outcome, SessionConfig};
use stm32_harness::tracking::run_trace;

/// Control tick budget, instructions (0.1 ms at 100 MHz, issue 30's target).
const TICK_BUDGET: u64 = 10_000;
/// Design budget, seconds (the ATmega2560's: 100 ms).
const DESIGN_BUDGET_S: f64 = 0.1;
/// Smallest free-run fit (%) of the identified model on a fresh host-side validation signal.
const MIN_FRESH_FIT: f64 = 70.0;
/// The fresh validation signal: a record the firmware neither estimates nor validates on (its
/// own records are random flow steps, `flow-steps`).
const FRESH_RECORD: Record = Record::BRamp;
/// Largest coefficient difference between the firmware (f32) and ridge-core on the host (f64)
/// from the same samples, relative to max(1, |coefficient|).
const COEF_TOL: f64 = 1e-4;

fn transcript(o: &Outcome) -> String {
    common::transcript(&o.bench)
}

fn assert_clean(what: &str, o: &Outcome, bad: Vec<String>) {
    assert!(
        bad.is_empty(),
        "{what}:\n- {}\nfirmware said:\n{}",
        bad.join("\n- "),
        transcript(o)
    );
}

/// Checks of one identification session; returns the list of failures.
fn check_identification(o: &Outcome) -> Vec<String> {
    let config = Config::default();
    let mut bad = Vec::new();
    let m = &o.bench.machine;
    if m.resets.len() != 1 || !m.faults.is_empty() {
        bad.push(format!("resets {:?}, CPU faults {:?}", m.resets, m.faults));
    }
    if o.accept.is_none() {
        bad.push("no ACCEPT line".into());
    }
    if !o.faults.is_empty() {
        bad.push(format!("FAULT lines: {:?}", o.faults));
    }
    if o.timing.control_worst > TICK_BUDGET || o.timing.ticks < 1000 {
        bad.push(format!(
            "control tick worst {} instructions (budget {TICK_BUDGET}) over {} ticks",
            o.timing.control_worst, o.timing.ticks
        ));
    }
    let Some(id) = &o.id else {
        bad.push("no ID line".into());
        return bad;
    };
    let Some(est) = &o.estimation else {
        bad.push("estimation record not rebuilt from the served frames".into());
        return bad;
    };
    if est.len() != usize::from(config.records.samples) || est.map != o.map {
        bad.push(format!(
            "estimation record of {} samples, map {:?} (the model's {:?})",
            est.len(),
            est.map,
            o.map
        ));
    }
    match host_search(est) {
        Ok(host) => match coefficient_error(&id.model, &host.model) {
            Some(e) if e <= COEF_TOL => {}
            e => bad.push(format!(
                "firmware {id:?} vs host {host:?}: coefficient difference {e:?}"
            )),
        },
        Err(e) => bad.push(format!("host search failed: {e}")),
    }
    match id.model.arx() {
        Err(_) => bad.push("ID line does not give a valid model".into()),
        Ok(model) => {
            let cfg = o.bench.config();
            let period = o.bench.duty_log.last().map_or(1, |d| d.period);
            let fresh = session::fresh_record(
                &FreshRecord {
                    pump: &cfg.pump,
                    lung: cfg.lung.as_ref(),
                    sensor: &cfg.sensor,
                    seed: cfg.seed + 1000,
                    record: FRESH_RECORD,
                    map: o.map,
                    base: config.base_duty,
                    latency: session::write_latency(&o.bench, est),
                },
                period,
            );
            match score(&model, &fresh).0 {
                Some(f) if f >= MIN_FRESH_FIT => {
                    println!("fresh validation ({FRESH_RECORD:?}) free-run fit {f:.1} %")
                }
                f => bad.push(format!(
                    "fresh validation free-run fit {f:?} < {MIN_FRESH_FIT} %"
                )),
            }
        }
    }
    bad
}

fn session(pump: PumpParams, seed: u64) -> Outcome {
    let mut cfg = SessionConfig::new(elf());
    cfg.bench.pump = pump;
    cfg.bench.seed = seed;
    session::run(&cfg).expect("session")
}

#[test]
fn small_blower_identifies() {
    let o = session(PumpParams::small(), 7);
    let bad = check_identification(&o);
    assert_clean("small blower, seed 7", &o, bad);
}

#[test]
fn sluggish_blower_identifies() {
    let o = session(PumpParams::sluggish(), 11);
    let bad = check_identification(&o);
    assert_clean("sluggish blower, seed 11", &o, bad);
}

/// Identification, design and the demo program in run mode on `blower` with `outlet`, then
/// the checks every run must pass; returns the scores.
fn tracking_run(
    blower: pump_sim::Blower,
    outlet: pump_sim::Outlet,
    seed: u64,
) -> pump_sim::baseline::experiment::Scores {
    let plant = pump_sim::PlantArgs::preset(blower, outlet);
    let what = plant.describe();
    let mut cfg = SessionConfig::new(elf());
    cfg.bench.pump = plant.pump();
    cfg.bench.lung = plant.lung().expect("lung preset");
    cfg.bench.seed = seed;
    cfg.track_s = f64::from(pump_sim::baseline::experiment::run_ticks()) * 0.01 + 0.5;
    let o = session::run(&cfg).expect("session");
    let mut bad = Vec::new();
    if o.accept.is_none() {
        bad.push("no ACCEPT line".to_string());
    }
    if !o.faults.is_empty() {
        bad.push(format!("FAULT lines: {:?}", o.faults));
    }
    if o.bench.find("ALARM").next().is_some() {
        bad.push("a tracking ALARM on the demo program".into());
    }
    if o.bench.machine.resets.len() != 1 {
        bad.push(format!("resets {:?}", o.bench.machine.resets));
    }
    match o.timing.design_ps {
        Some(t) if secs(t) < DESIGN_BUDGET_S => {}
        t => bad.push(format!("design {:?} s ≥ {DESIGN_BUDGET_S} s", t.map(secs))),
    }
    let run = match run_trace(&o.bench) {
        Ok(r) => r,
        Err(e) => {
            bad.push(format!("no run mode: {e}"));
            assert_clean(&what, &o, bad);
            unreachable!()
        }
    };
    if let Err(e) = run.track_check() {
        bad.push(e);
    }
    let control: Vec<u64> = o.bench.machine.core().ticks.ticks[run.first_tick..]
        .iter()
        .filter_map(|t| t.control_instr)
        .collect();
    let worst = control.iter().copied().max();
    println!(
        "{what}: run-mode control tick worst {worst:?} instructions over {} ticks",
        control.len()
    );
    match worst {
        Some(w) if w <= TICK_BUDGET && control.len() > 1000 => {}
        w => bad.push(format!(
            "run-mode control tick worst {w:?} instructions over {} ticks (budget {TICK_BUDGET})",
            control.len()
        )),
    }
    let scores = run.scores();
    if scores.is_none() {
        bad.push("run mode too short to score".into());
    }
    assert_clean(&what, &o, bad);
    scores.expect("scores")
}

/// Steady-state error within the sensor noise on every level (σ: the SFM3300 model's noise,
/// 3 % of the flow), the largest overshoot and the breath RMS (% of the 60 slm peak) within
/// `overshoot_max` and `breath_max`.
fn assert_tracks(
    what: &str,
    sc: &pump_sim::baseline::experiment::Scores,
    overshoot_max: f64,
    breath_max: f64,
) {
    let over = sc
        .steps
        .iter()
        .flatten()
        .map(|m| m.overshoot_pct)
        .fold(0.0, f64::max);
    let ss = sc
        .steps
        .iter()
        .flatten()
        .map(|m| m.ss_error.abs())
        .fold(0.0, f64::max);
    println!(
        "{what}: largest overshoot {over:.1} %, largest |e_ss| {ss:.3} slm, breath RMS {:.2} slm ({:.2} % of peak), duty TV {:.0} %/s",
        sc.breath_rms,
        breath_pct(sc.breath_rms),
        100.0 * sc.duty_tv
    );
    let sensor = pump_sim::sfm3300::Sfm3300Params::default();
    for (m, level) in sc.steps.iter().zip(&sc.levels) {
        let m = m
            .as_ref()
            .unwrap_or_else(|| panic!("{what}: step to {level} not scored"));
        let sigma = sensor.noise_std(*level);
        assert!(
            m.ss_error.abs() <= sigma,
            "{what}: steady-state error {:.3} slm at {level} slm > σ {sigma:.3}",
            m.ss_error
        );
        assert!(
            m.overshoot_pct <= overshoot_max,
            "{what}: overshoot {:.1} % at {level} slm > {overshoot_max} %",
            m.overshoot_pct
        );
    }
    let breath = breath_pct(sc.breath_rms);
    assert!(
        breath <= breath_max,
        "{what}: breath RMS {breath:.2} % of peak > {breath_max} %"
    );
}

#[test]
fn tracks_default_blower_adult_lung() {
    let sc = tracking_run(pump_sim::Blower::Default, pump_sim::Outlet::Adult, 1);
    assert_tracks("default blower, adult lung", &sc, 10.0, 5.0);
}

#[test]
fn tracks_default_blower_stiff_lung() {
    let sc = tracking_run(pump_sim::Blower::Default, pump_sim::Outlet::Stiff, 2);
    // The simavr test's regression bound (the 10 % target is missed with the stiff lung).
    assert_tracks("default blower, stiff lung", &sc, 25.0, 5.0);
}

#[test]
fn tracks_small_blower_adult_lung() {
    let sc = tracking_run(pump_sim::Blower::Small, pump_sim::Outlet::Adult, 3);
    assert_tracks("small blower, adult lung", &sc, 10.0, 5.0);
}

#[test]
fn tracks_small_blower_stiff_lung() {
    let sc = tracking_run(pump_sim::Blower::Small, pump_sim::Outlet::Stiff, 4);
    // The simavr test's regression bound (the 10 % target is missed with the stiff lung).
    assert_tracks("small blower, stiff lung", &sc, 40.0, 5.0);
}

#[test]
fn tracks_sluggish_blower_adult_lung() {
    let sc = tracking_run(pump_sim::Blower::Sluggish, pump_sim::Outlet::Adult, 5);
    assert_tracks("sluggish blower, adult lung", &sc, 10.0, 5.0);
}

#[test]
fn tracks_sluggish_blower_stiff_lung() {
    let sc = tracking_run(pump_sim::Blower::Sluggish, pump_sim::Outlet::Stiff, 6);
    // The simavr test's regression bound (the 5 % breath target is missed by a hair).
    assert_tracks("sluggish blower, stiff lung", &sc, 10.0, 6.0);
}
