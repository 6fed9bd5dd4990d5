//! Run mode's re-identification (`ridge_pump_firmware::reid`) in the firmware's state machine
//! on the host, closed loop with pump-sim's plant and ISO 80601-2-12 row 1's test lung: the
//! swap path with a fit threshold set, at the breath boundary as the controller sees it; a
//! refused estimate that keeps the running controller; the default rule (a swap only while the
//! volume alarm is raised) with a refused re-design that says why; the lung change to C 10 R 50
//! with and without the swap; the drift and alarm trigger; the snapshot spread over the ticks
//! after the boundary's against the schedule that took it in one tick (a known ARX plant's
//! record, the reports bit for bit).
//!
//! Truths: the simulated lung (the volume it received each inspiration, from the plant's true
//! flow), the breath timing of the `VENT` settings (the valve's closures), the verdicts'
//! definitions (the figures on each `REID` report against the rule it names); for the
//! schedule, `ridge_core::reid` run directly with the snapshot in the boundary's tick.

use pump_sim::baseline::experiment::identify_with;
use pump_sim::iso::iso_row;
use pump_sim::vent_bench::power_up_plant;
use pump_sim::LungParams;
use ridge_pump_firmware::command::VentArgs;
use ridge_pump_firmware::event::{ControlRefusal, Event, ReidVerdict};
use ridge_pump_firmware::reid::{ReidConfig, SwapRule};
use ridge_pump_firmware::selfid::{Config, SelfIdentification};
use ridge_pump_firmware::setpoint::Shape;
use ridge_pump_firmware::units::FLOW_OFFSET;

/// The defaults with the swap rule on at 80 % (the threshold the first device run used).
static SWAP_AT_80: Config = Config {
    frozen_ticks: 0,
    reid: ReidConfig {
        swap: SwapRule::BelowFit(80.0),
        ..ReidConfig::DEFAULT
    },
    ..Config::DEFAULT
};

/// The defaults, but a re-estimate only on a drift or an alarm (`every` far beyond the run).
static ON_ALARM: Config = Config {
    frozen_ticks: 0,
    reid: ReidConfig {
        every: 1_000,
        ..ReidConfig::DEFAULT
    },
    ..Config::DEFAULT
};

/// The defaults (a swap only while the volume alarm is raised).
static DEFAULTS: Config = Config {
    frozen_ticks: 0,
    ..Config::DEFAULT
};

fn row1_lung() -> LungParams {
    iso_row(1).expect("row 1").lung(&LungParams::adult())
}

/// `VENT vt=VT rate=20 ti=1 wave=square peep=5 trim=on` (`vt` in mL).
fn vent(vt: i32) -> VentArgs {
    VentArgs {
        ti: Some(1_000),
        wave: Some(Shape::Square),
        peep: Some(5_000),
        trim: Some(true),
        ..VentArgs::new(vt * 1_000, 20_000)
    }
}

/// A ventilated run: the events, the lung's volumes, the swaps.
struct Run {
    events: Vec<Event>,
    /// The breath in progress (from 1) when each event came.
    event_breaths: Vec<usize>,
    /// Per breath (from 1): the volume the lung received while the valve was closed, mL.
    delivered: Vec<f64>,
    /// Controller swaps seen (the controller's parameters changed), at these breaths.
    swaps: Vec<u32>,
    /// The tick of each swap (the interval its control started) and the preview before it.
    swap_ticks: Vec<(usize, u8)>,
    /// The interval each breath started at (the valve closed for it).
    breath_ticks: Vec<usize>,
}

/// Identifies on row 1's lung with its PEEP valve at 0 (as the stored model of the device
/// tests), then ventilates with `args` for `breaths` breaths on row 1's lung (PEEP 5).
fn ventilate(config: &'static Config, args: &VentArgs, breaths: u32) -> Run {
    ventilate_changing(config, args, breaths, None)
}

/// [`ventilate`], the lung becoming `change.1` as breath `change.0` starts.
fn ventilate_changing(
    config: &'static Config,
    args: &VentArgs,
    breaths: u32,
    change: Option<(usize, LungParams)>,
) -> Run {
    let l = row1_lung();
    let plant = power_up_plant(&l);
    let (mut rig, mut sm, _): (_, SelfIdentification, _) =
        identify_with(&plant, 3, config).expect("identification");
    rig.lung.as_mut().expect("lung").set_params(l);
    sm.set_vent(args).expect("VENT");
    let ticks = 300 * (breaths + 1);
    let mut duty = sm.duty();
    let (mut events, mut delivered, mut swaps) = (Vec::new(), Vec::new(), Vec::new());
    let mut volume = 0.0;
    let mut closed_before = false;
    let mut ctrl = sm.controller().map(|c| format!("{:?}", c.rst()));
    let (mut swap_ticks, mut breath_ticks) = (Vec::new(), Vec::new());
    let mut event_breaths = Vec::new();
    for t in 0..ticks as usize {
        // The valve of the interval the last tick started.
        rig.valve = sm.valve();
        let closed = rig.valve == pump_sim::Valve::Closed;
        if closed && !closed_before {
            volume = 0.0;
            breath_ticks.push(t.saturating_sub(1));
            if let Some((at, lung)) = &change {
                if breath_ticks.len() == *at {
                    rig.lung.as_mut().expect("lung").set_params(lung.clone());
                }
            }
        }
        let flow = rig.true_flow(duty);
        if closed {
            volume += flow * 1000.0 / 60.0 * 0.01;
        }
        if !closed && closed_before {
            delivered.push(volume);
        }
        closed_before = closed;
        let word = rig.sensor.measure_raw(flow);
        let counts = (i32::from(word) - i32::from(FLOW_OFFSET)) as i16;
        let mut event = None;
        let preview = sm.preview().unwrap_or(0);
        duty = sm.tick_into(Ok(counts), &mut event);
        sm.after_write(&mut event);
        sm.after_pwm(&mut event);
        let now = sm.controller().map(|c| format!("{:?}", c.rst()));
        if now != ctrl {
            swaps.push(delivered.len() as u32 + 1);
            swap_ticks.push((t, preview));
            ctrl = now;
        }
        if let Some(e) = event {
            events.push(e);
            event_breaths.push(breath_ticks.len());
        }
        assert!(sm.fault().is_none(), "fault: {:?}", sm.fault());
    }
    Run {
        events,
        event_breaths,
        delivered,
        swaps,
        swap_ticks,
        breath_ticks,
    }
}

fn reports(run: &Run) -> Vec<ridge_pump_firmware::event::ReidReport> {
    run.events
        .iter()
        .filter_map(|e| match e {
            Event::Reid(r) => Some(*r),
            _ => None,
        })
        .collect()
}

/// Each verdict among `events` against the rule it names (`min_fit` 70 %, the swap rule
/// `rule`, the volume alarm as the `ALARM volume` lines before it raised and cleared it).
fn check_verdicts(events: &[Event], rule: SwapRule) {
    let mut alarm = false;
    for e in events {
        let r = match e {
            Event::VolumeAlarm { on, .. } => {
                alarm = *on;
                continue;
            }
            Event::Reid(r) => r,
            _ => continue,
        };
        let swap = match rule {
            SwapRule::Never => false,
            SwapRule::VolumeAlarm => alarm,
            SwapRule::BelowFit(below) => r.running < below,
        };
        match r.verdict {
            ReidVerdict::Accepted => {
                assert!(r.fit >= 70.0 && r.fit >= r.running, "{r:?}");
                assert!(swap, "{r:?} under {rule:?}, alarm {alarm}");
            }
            ReidVerdict::Kept => {
                assert!(r.fit >= 70.0 && r.fit >= r.running, "{r:?}");
                assert!(!swap, "{r:?} under {rule:?}, alarm {alarm}");
            }
            ReidVerdict::Fit => assert!(r.fit < 70.0 || r.fit < r.running, "{r:?}"),
            ReidVerdict::NotExcited => assert!(r.v_rms < 5.0, "{r:?}"),
            ReidVerdict::Model => assert!(!(0.5..=2.0).contains(&r.gain), "{r:?}"),
            _ => {}
        }
    }
}

/// With the swap rule on at 80 % the adult lung's power-up controller is swapped (its model's
/// held-out fit is far below 80 %, identified without the PEEP and exhalation valves), at a
/// breath boundary, bumplessly: every breath after a swap delivers within ±(4 mL + 15 %).
#[test]
fn an_accepted_estimate_is_swapped_in_at_a_breath_boundary_bumplessly() {
    let run = ventilate(&SWAP_AT_80, &vent(500), 12);
    let reports = reports(&run);
    for r in &reports {
        println!("{r:?}");
    }
    println!("swaps at breaths {:?}", run.swaps);
    for (k, v) in run.delivered.iter().enumerate() {
        println!("breath {:2}: {v:6.1} mL", k + 1);
    }
    check_verdicts(&run.events, SwapRule::BelowFit(80.0));
    let accepted = reports
        .iter()
        .filter(|r| r.verdict == ReidVerdict::Accepted)
        .count();
    assert!(accepted >= 1, "{reports:?}");
    // One controller swap per accepted estimate (none from elsewhere), each at the breath
    // boundary as the controller sees it: the next breath starts as many ticks later as the
    // controller previewed the program before the swap.
    assert_eq!(run.swaps.len(), accepted, "{:?}", run.swaps);
    // The swapped model's monitor takes a new ventilated baseline: no `DRIFT` on the steady
    // lung.
    assert!(
        !run.events.iter().any(|e| matches!(e, Event::Drift { .. })),
        "DRIFT after a swap"
    );
    for &(t, preview) in &run.swap_ticks {
        assert!(
            run.breath_ticks.contains(&(t + usize::from(preview))),
            "swap at tick {t}, preview {preview}, breaths at {:?}",
            run.breath_ticks
        );
    }
    // From breath 2 on (the first is the program's start from the settled flow) every breath
    // is within the standards' band, the swapped ones included.
    for (k, &v) in run.delivered.iter().enumerate().skip(1) {
        assert!(
            (v - 500.0).abs() <= 4.0 + 0.15 * 500.0,
            "breath {}: {v:.1} mL (swaps at {:?})",
            k + 1,
            run.swaps
        );
    }
}

/// Breaths too small to excite the loop (100 mL on the 5 slm bias flow: the map's flow moves by
/// 2.1–3.2 slm RMS, below the 5 slm of `ReidConfig::min_input_response`) give `not-excited`
/// estimates, and the controller is never swapped, even with the rule on.
#[test]
fn a_refused_estimate_keeps_the_running_controller() {
    let run = ventilate(&SWAP_AT_80, &vent(100), 8);
    let reports = reports(&run);
    for r in &reports {
        println!("{r:?}");
    }
    check_verdicts(&run.events, SwapRule::BelowFit(80.0));
    assert!(reports.len() >= 3, "{reports:?}");
    assert!(
        reports.iter().all(|r| r.verdict == ReidVerdict::NotExcited),
        "{reports:?}"
    );
    assert!(run.swaps.is_empty(), "{:?}", run.swaps);
}

/// The default settings on the same lung (no volume alarm): estimates made and kept, never
/// swapped.
#[test]
fn with_the_default_settings_no_controller_is_swapped() {
    let run = ventilate(&DEFAULTS, &vent(500), 8);
    let reports = reports(&run);
    check_verdicts(&run.events, SwapRule::VolumeAlarm);
    assert!(
        reports.iter().any(|r| r.verdict == ReidVerdict::Kept),
        "{reports:?}"
    );
    assert!(run.swaps.is_empty(), "{:?}", run.swaps);
}

/// Row 1's lung becomes C 10 R 50 as breath 10 starts. With the default settings (swap only on
/// the volume alarm, which the power-up controller with the volume trim never raises here)
/// every breath from two after the change is within ±(4 mL + 5 %) of 500 mL (measured: −0.1 to
/// −0.5 %). With the swap rule at 80 % the adult lung's controller is swapped twice (its
/// model's held-out fit is far below 80 %) for re-designs of adult-lung estimates (at the
/// power-up design's speed), and on the stiff lung those deliver every breath more than 5 %
/// short (measured −5.5 to −6.0 %; −15 % when the re-design took its speed from the estimate),
/// within ±(4 mL + 15 %): the reason the fit rule is not the default (docs/ventilation.md).
/// Both runs' verdicts follow their rules.
#[test]
fn after_a_lung_change_the_default_stays_in_the_band_and_the_swap_would_not() {
    let stiff = LungParams {
        compliance: 10.0,
        resistance: 50.0,
        ..row1_lung()
    };
    let in_band = |v: f64| (v - 500.0).abs() <= 4.0 + 0.15 * 500.0;
    let in_band5 = |v: f64| (v - 500.0).abs() <= 4.0 + 0.05 * 500.0;
    for (config, swap) in [(&DEFAULTS, None), (&SWAP_AT_80, Some(80.0))] {
        let run = ventilate_changing(config, &vent(500), 20, Some((10, stiff.clone())));
        let reports = reports(&run);
        println!("swap rule {swap:?}: swaps at breaths {:?}", run.swaps);
        for r in &reports {
            println!("  {r:?}");
        }
        let after: Vec<f64> = run.delivered.iter().skip(11).copied().collect();
        println!("  breaths 12-: {after:.1?}");
        check_verdicts(&run.events, config.reid.swap);
        assert!(after.len() >= 9, "{after:?}");
        if swap.is_none() {
            assert!(run.swaps.is_empty(), "{:?}", run.swaps);
            assert!(after.iter().all(|&v| in_band5(v)), "{after:?}");
        } else {
            assert!(!run.swaps.is_empty());
            assert!(
                after.iter().all(|&v| in_band(v) && v < 500.0 * 0.95),
                "{after:?}"
            );
        }
    }
}

/// With re-estimates only on a drift or an alarm (`every` 1 000 breaths): they start at the
/// first breath boundary after the first `DRIFT` or alarm, and not before. On row 1's steady
/// lung nothing triggers one (the monitor compares the breaths with its ventilated baseline,
/// breath 3); its change to C 10 R 50 as breath 10 starts raises `DRIFT` within two breaths
/// (`monitor`'s breath rule), and the drift flag stays raised, so from then on a re-estimate
/// starts at every free boundary, as with `every` 1.
#[test]
fn a_drift_or_an_alarm_starts_a_re_estimate() {
    let stiff = LungParams {
        compliance: 10.0,
        resistance: 50.0,
        ..row1_lung()
    };
    let run = ventilate_changing(&ON_ALARM, &vent(500), 16, Some((10, stiff)));
    let first_trigger = run
        .events
        .iter()
        .zip(&run.event_breaths)
        .find(|(e, _)| {
            matches!(
                e,
                Event::Drift { .. }
                    | Event::Alarm { on: true, .. }
                    | Event::VolumeAlarm { on: true, .. }
            )
        })
        .map(|(_, &b)| b)
        .expect("no DRIFT or alarm");
    let reports = reports(&run);
    println!(
        "first DRIFT or alarm in breath {first_trigger}; REID breaths {:?}",
        reports.iter().map(|r| r.breath).collect::<Vec<_>>()
    );
    assert!((10..=12).contains(&first_trigger), "{first_trigger}");
    assert!(!reports.is_empty());
    assert_eq!(reports[0].breath as usize, first_trigger + 1, "{reports:?}");
    check_verdicts(&run.events, SwapRule::VolumeAlarm);
}

/// The defaults with the duty limited to 50 % (`ControlConfig::duty_max` 5 000): row 1's
/// square breath (30 slm) needs more than the blower gives there, so every breath is short.
static DUTY_50: Config = Config {
    control: ridge_pump_firmware::selfid::ControlConfig {
        duty_max: 5_000,
        ..Config::DEFAULT.control
    },
    ..DEFAULTS
};

/// The default swap rule lets an estimate through only while the volume alarm is raised. With
/// the duty limited to 50 % the lung receives 16–18 % less than the 500 mL set (the truth: the
/// simulated lung's volume), the alarm rises from breath 3, and the estimates that pass their
/// checks while it is raised go to the re-design, which refuses them: every one has more than
/// one slow pole or a slow complex pair (`why=slow-poles`; their gain, 0.95–1.01, passes the
/// model check), so the running controller stays (no swap), and each `REID` line says so.
/// Measured: 6 of 6 estimates refused so, breaths 4–14 at 413–415 mL. Before the alarm the
/// estimates are `kept` (the rule), and no verdict breaks its rule.
#[test]
fn on_the_volume_alarm_a_refused_re_design_keeps_the_running_controller_and_says_why() {
    let run = ventilate(&DUTY_50, &vent(500), 14);
    let reports = reports(&run);
    for r in &reports {
        println!("{r:?}");
    }
    println!("delivered {:.1?}", run.delivered);
    check_verdicts(&run.events, SwapRule::VolumeAlarm);
    // The lung's truth: short by more than the alarm's band from breath 2 on.
    assert!(
        run.delivered
            .iter()
            .skip(1)
            .all(|&v| v < 500.0 - (4.0 + 0.15 * 500.0)),
        "{:?}",
        run.delivered
    );
    assert!(run
        .events
        .iter()
        .any(|e| matches!(e, Event::VolumeAlarm { on: true, .. })));
    let refused: Vec<_> = reports
        .iter()
        .filter(|r| matches!(r.verdict, ReidVerdict::Design(_)))
        .collect();
    assert!(refused.len() >= 3, "{reports:?}");
    for r in &refused {
        // Past the model check (the design's own gain limits), refused by the design.
        assert!((0.5..=2.0).contains(&r.gain), "{r:?}");
        assert!(
            matches!(
                r.verdict,
                ReidVerdict::Design(ControlRefusal::Design { tries, .. }) if tries >= 1
            ),
            "{r:?}"
        );
    }
    assert!(run.swaps.is_empty(), "{:?}", run.swaps);
}

/// A record `(v, y)` in counts of a known ARX plant (p 2, q 2, d 1, an intercept; static gain
/// 0.75) driven by breath-like steps (30 slm for 100 ticks, 5 for 200) with a small dither, the
/// output with a small deterministic noise.
fn known_breaths(ticks: usize) -> Vec<(i16, i16)> {
    let counts = |slm: f32| (slm / ridge_pump_firmware::units::SLM_PER_COUNT).round() as i16;
    let mut state = 0x2545_f491_u32;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state % 2001) as f32 / 1000.0 - 1.0
    };
    let (mut y1, mut y2, mut u1, mut u2) = (0.0f32, 0.0, 0.0, 0.0);
    (0..ticks)
        .map(|t| {
            let u = if t % 300 < 100 { 30.0 } else { 5.0 } + noise();
            let y = 1.1 * y1 - 0.3 * y2 + 0.1 * u1 + 0.05 * u2 + 0.5 + 0.1 * noise();
            (y2, y1, u2, u1) = (y1, y, u1, u);
            (counts(u), counts(y))
        })
        .collect()
}

/// The breath that starts at tick `t` of [`known_breaths`]: every 300 ticks, and a first one
/// after 5 ticks, whose window is too short for a snapshot (none starts; the next boundary
/// tries).
fn breath_at(t: usize) -> Option<u32> {
    match t {
        5 => Some(1),
        _ if t > 0 && t % 300 == 0 => Some(t as u32 / 300 + 1),
        _ => None,
    }
}

/// The re-identification's reports (breath, verdict, gain, fit, running, `v` RMS as bit
/// patterns) on `record`, breaths starting as [`breath_at`] says, as the schedule before the snapshot was spread
/// over ticks computed them, from `ridge_core::reid` directly: every sample into the window,
/// the snapshot (`Refit::start`) and the first unit in the boundary's tick, one unit a tick, a
/// finished fit's checks in its last unit's tick, the verdict at the first boundary with a
/// breath of samples held out.
fn one_tick_snapshot_reports(
    record: &[(i16, i16)],
    running: ridge_core::ArxModel<f32>,
    accept: ridge_core::reid::Acceptance<f32>,
) -> Vec<(u32, &'static str, [u32; 4])> {
    use ridge_core::reid::{Holdout, Refit, RefitStep, Window, WINDOW_LEN_MAX};
    use ridge_pump_firmware::units::{MODEL_SCALE, SLM_PER_COUNT};
    enum Job {
        Idle,
        Fit(Box<Refit<f32>>, u32),
        Hold(Box<Holdout<f32>>, ridge_core::ArxModel<f32>, u32, f32),
    }
    let method = ridge_core::RidgeM::PAPER;
    let mut store = [0i64; WINDOW_LEN_MAX];
    let mut w = Window::new(
        running.structure(),
        running.offset(),
        ridge_pump_firmware::reid::SHIFT,
        &mut store,
    )
    .unwrap();
    let (mut job, mut out) = (Job::Idle, Vec::new());
    let bits = |g: f32, f: f32, r: f32, v: f32| [g, f, r, v].map(f32::to_bits);
    for (t, &(v, y)) in record.iter().enumerate() {
        w.push(v, y).unwrap();
        let boundary = breath_at(t);
        if let Some(breath) = boundary {
            w.end_breath();
            if let Job::Hold(h, m, b, v_rms) = &job {
                if h.scored() >= accept.holdout_min {
                    let v = accept.judge(h).unwrap();
                    out.push((
                        *b,
                        "kept",
                        bits(m.static_gain(), v.candidate.fit, v.running.fit, *v_rms),
                    ));
                    job = Job::Idle;
                }
            }
            if matches!(job, Job::Idle) {
                if let Ok(r) = Refit::start(&w, method, &MODEL_SCALE) {
                    job = Job::Fit(Box::new(r), breath);
                }
            }
        }
        let (u, y) = (f32::from(v) * SLM_PER_COUNT, f32::from(y) * SLM_PER_COUNT);
        match &mut job {
            Job::Idle => {}
            Job::Fit(r, b) => match r.step(1) {
                RefitStep::Working => {}
                RefitStep::Done(m, _) => {
                    let (b, v_rms) = (*b, r.input_response());
                    job = match accept.check_estimate(&m, r.response(), v_rms) {
                        Ok(_) => Job::Hold(Box::new(Holdout::new(m, running)), m, b, v_rms),
                        Err(_) => {
                            out.push((b, "refused", bits(m.static_gain(), 0.0, 0.0, v_rms)));
                            Job::Idle
                        }
                    };
                }
                RefitStep::Refused(_) => panic!("numeric refusal"),
            },
            Job::Hold(h, ..) => h.push(u, y),
        }
    }
    out
}

#[test]
fn the_snapshot_spread_over_ticks_reports_what_a_snapshot_in_one_tick_did() {
    let record = known_breaths(300 * 12);
    // The running model with twice the plant's input gain: every estimate passes and is kept.
    let running = ridge_core::ArxModel::new(
        &[1.1f32, -0.3],
        &[0.2, 0.1],
        1,
        ridge_core::Offset::Intercept,
        0.5,
    )
    .unwrap();
    let cfg = Config::DEFAULT;
    let mut reid = cfg.reidentification(running, 300);
    let accept = ridge_core::reid::Acceptance {
        model: cfg.control.model,
        min_response: cfg.min_response,
        min_input_response: cfg.reid.min_input_response,
        min_fit: cfg.min_fit,
        holdout_min: 300,
    };
    let mut got = Vec::new();
    for (t, &(v, y)) in record.iter().enumerate() {
        let boundary = breath_at(t);
        assert_eq!(reid.after_pwm(v, y, boundary, false, false), None);
        if let Some(r) = reid.take_report() {
            let kind = match r.verdict {
                ReidVerdict::Kept => "kept",
                _ => "refused",
            };
            let (fit, running) = if kind == "kept" {
                (r.fit, r.running)
            } else {
                (0.0, 0.0)
            };
            got.push((
                r.breath,
                kind,
                [r.gain, fit, running, r.v_rms].map(f32::to_bits),
            ));
        }
    }
    let want = one_tick_snapshot_reports(&record, running, accept);
    assert!(
        want.len() >= 4 && want.iter().all(|r| r.1 == "kept"),
        "{want:?}"
    );
    assert_eq!(got, want);
}
