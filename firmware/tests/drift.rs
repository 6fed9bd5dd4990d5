//! The run-mode monitor's `DRIFT` while a volume program runs ([`ridge_pump_firmware::monitor`],
//! "While ventilating"), in the firmware's state machine on the host, closed loop with
//! pump-sim's plant, ISO 80601-2-12 rows 1, 4 and 7's test lungs and the SFM3300's noise
//! (3 % of the reading): no `DRIFT` without a change of the lung; `DRIFT` within two breaths
//! of a change of compliance, resistance or a leak; with `MonitorConfig::reidentify` on, a
//! drift while ventilating is reported and the breaths go on (no power-up identification).
//!
//! Truths: the simulated lung and its changes (set by the test at a breath's start), the
//! breath timing of the `VENT` settings (the valve's closures, counted by the test).

use pump_sim::baseline::experiment::identify_with;
use pump_sim::iso::iso_row;
use pump_sim::vent_bench::power_up_plant;
use pump_sim::LungParams;
use ridge_pump_firmware::command::VentArgs;
use ridge_pump_firmware::event::Event;
use ridge_pump_firmware::monitor::MonitorConfig;
use ridge_pump_firmware::selfid::{Config, SelfIdentification, State};
use ridge_pump_firmware::setpoint::Shape;
use ridge_pump_firmware::units::FLOW_OFFSET;

/// The defaults (the frozen-sensor check off: the simulated sensor may repeat a reading).
static DEFAULTS: Config = Config {
    frozen_ticks: 0,
    ..Config::DEFAULT
};

/// The defaults with a new identification on a drift.
static REIDENTIFY: Config = Config {
    frozen_ticks: 0,
    monitor: MonitorConfig {
        reidentify: true,
        ..MonitorConfig::DEFAULT
    },
    ..Config::DEFAULT
};

/// The breath at whose start the lung changes.
const CHANGE: usize = 10;

/// A ventilated run's `DRIFT` events and what the test saw.
struct Run {
    /// The breaths (from 1, counted from the valve's closures) in which a `DRIFT` came.
    drifts: Vec<usize>,
    /// Breaths started (valve closures).
    breaths: usize,
    /// `BREATH` lines.
    breath_lines: usize,
    /// Ticks in run mode after the program started (all of them unless it left run mode).
    run_ticks: usize,
    /// Per breath (index 0 the lead-in): Σ residual and samples of the `RES`/`DRIFT` windows
    /// that closed in it (1 s windows, three to a breath at 20 /min), slm.
    windows: Vec<(f32, f32)>,
}

impl Run {
    /// Breaths 4 to `last`: the mean residual of each minus breath 3's (the baseline), slm,
    /// from the windows (a figure to print beside the firmware's decision).
    fn deviations(&self, last: usize) -> Vec<f32> {
        let mean = |b: usize| self.windows.get(b).map_or(f32::NAN, |(s, n)| s / n);
        (4..=last).map(|b| mean(b) - mean(3)).collect()
    }
}

/// Identifies on row `row`'s lung with its PEEP valve at 0 (the power-up plant), then
/// ventilates with the row's settings (square wave, the trim on) for `breaths` breaths, the
/// lung becoming `change` as breath [`CHANGE`] starts.
fn ventilate(
    config: &'static Config,
    row: u8,
    seed: u64,
    change: Option<&LungParams>,
    breaths: u32,
) -> Run {
    let r = iso_row(row).expect("row");
    let lung = r.lung(&LungParams::adult());
    let (mut rig, mut sm, _): (_, SelfIdentification, _) =
        identify_with(&power_up_plant(&lung), seed, config).expect("identification");
    rig.lung.as_mut().expect("lung").set_params(lung);
    let args = VentArgs {
        vt: (r.tidal * 1e3) as i32,
        rate: (r.rate * 1e3) as i32,
        ti: None,
        ie: Some((r.ie * 1e3) as i32),
        wave: Some(Shape::Square),
        peep: Some((r.peep * 1e3) as i32),
        bias: None,
        rise: None,
        trim: Some(true),
    };
    sm.set_vent(&args).expect("VENT");
    let ticks = (60.0 / r.rate * 100.0) as usize * (breaths as usize + 1);
    let mut duty = sm.duty();
    let mut closed_before = false;
    let mut run = Run {
        drifts: Vec::new(),
        breaths: 0,
        breath_lines: 0,
        run_ticks: 0,
        windows: vec![(0.0, 0.0); breaths as usize + 2],
    };
    for _ in 0..ticks {
        rig.valve = sm.valve();
        let closed = rig.valve == pump_sim::Valve::Closed;
        if closed && !closed_before {
            run.breaths += 1;
            if let (Some(l), true) = (change, run.breaths == CHANGE) {
                rig.lung.as_mut().expect("lung").set_params(l.clone());
            }
        }
        closed_before = closed;
        let flow = rig.true_flow(duty);
        let word = rig.sensor.measure_raw(flow);
        let counts = (i32::from(word) - i32::from(FLOW_OFFSET)) as i16;
        let mut event = None;
        duty = sm.tick_into(Ok(counts), &mut event);
        sm.after_write(&mut event);
        sm.after_pwm(&mut event);
        let window = match event {
            Some(Event::Drift { residuals, .. }) => {
                run.drifts.push(run.breaths);
                Some(residuals)
            }
            Some(Event::Residual(r)) => Some(r),
            Some(Event::Breath(_)) => {
                run.breath_lines += 1;
                None
            }
            _ => None,
        };
        if let (Some(r), Some(w)) = (window, run.windows.get_mut(run.breaths)) {
            w.0 += r.sum;
            w.1 += f32::from(r.samples);
        }
        assert!(sm.fault().is_none(), "fault: {:?}", sm.fault());
        if sm.state() == State::Run {
            run.run_ticks += 1;
        }
    }
    assert!(run.breaths >= breaths as usize, "{} breaths", run.breaths);
    run
}

/// A lung change: its name, the ISO row, what it does to the row's lung.
type Change = (&'static str, u8, fn(&mut LungParams));

/// Row `row`'s lung with `f` applied.
fn changed(row: u8, f: impl Fn(&mut LungParams)) -> LungParams {
    let mut l = iso_row(row).expect("row").lung(&LungParams::adult());
    f(&mut l);
    l
}

/// Without a change of the lung no `DRIFT` comes in 20 breaths, on rows 1, 4 and 7 and seeds
/// 1-5 (the power-up model, identified without the PEEP and exhalation valves, mispredicts
/// every breath; the breath rule compares each breath with the baseline breath, not with the
/// limits of the windows).
#[test]
fn no_drift_while_the_lung_stays() {
    for row in [1, 4, 7] {
        for seed in 1..=5 {
            let run = ventilate(&DEFAULTS, row, seed, None, 20);
            let dev = run.deviations(19);
            let worst = dev.iter().fold(0.0f32, |m, d| m.max(d.abs()));
            println!(
                "row {row} seed {seed}: DRIFT in breaths {:?}; breaths 4-19 within {worst:.3} slm of breath 3",
                run.drifts
            );
            assert!(
                run.drifts.is_empty(),
                "row {row} seed {seed}: {:?}",
                run.drifts
            );
        }
    }
}

/// A change of the lung at breath 10 (C -> 10 mL/cmH2O, R -> 50 cmH2O/(L/s), a leak of
/// 100 cmH2O/(L/s) to the room) raises `DRIFT` within the breath rule's two breaths (the
/// changed breath and the next, so it comes in breath 12), and no earlier, on rows 1 and 4 (and
/// row 7 with the leak: row 7's lung already is C 10, R 50), seeds 1-5.
#[test]
fn a_lung_change_raises_drift_within_two_breaths() {
    let cases: [Change; 7] = [
        ("C 10", 1, |l| l.compliance = 10.0),
        ("R 50", 1, |l| l.resistance = 50.0),
        ("leak", 1, |l| l.leak = Some(100.0)),
        ("C 10", 4, |l| l.compliance = 10.0),
        ("R 50", 4, |l| l.resistance = 50.0),
        ("leak", 4, |l| l.leak = Some(100.0)),
        ("leak", 7, |l| l.leak = Some(100.0)),
    ];
    for (name, row, f) in cases {
        for seed in 1..=5 {
            let run = ventilate(&DEFAULTS, row, seed, Some(&changed(row, f)), 16);
            let dev = run.deviations(15);
            println!(
                "row {row} {name} seed {seed}: DRIFT in breaths {:?}; breaths 10-15 minus breath 3 {:.2?} slm",
                run.drifts,
                dev.get(6..).unwrap_or(&[])
            );
            assert_eq!(run.drifts.len(), 1, "row {row} {name} seed {seed}");
            let after = run.drifts[0] - CHANGE;
            assert!(after <= 2, "row {row} {name} seed {seed}: {:?}", run.drifts);
        }
    }
}

/// With a new identification on a drift (`MonitorConfig::reidentify`), a drift while
/// ventilating (row 1's lung to C 10 at breath 10) is reported and the state machine stays in
/// run mode: every breath of the 16 is started and reported.
#[test]
fn a_drift_while_ventilating_does_not_start_an_identification() {
    let stiff = changed(1, |l| l.compliance = 10.0);
    let run = ventilate(&REIDENTIFY, 1, 1, Some(&stiff), 16);
    println!(
        "DRIFT in breaths {:?}; {} breaths, {} BREATH lines",
        run.drifts, run.breaths, run.breath_lines
    );
    assert_eq!(run.drifts.len(), 1, "{:?}", run.drifts);
    // Row 1: 20 /min, 300 ticks a breath; the run is 17 breaths long.
    assert_eq!(run.run_ticks, 300 * 17);
    assert!(
        run.breaths >= 16 && run.breath_lines >= 15,
        "{}",
        run.breath_lines
    );
}
