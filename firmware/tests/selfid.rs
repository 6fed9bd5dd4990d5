//! The self-identification state machine driven in closed loop by synthetic plants simulated
//! inside the tests (integer sensor counts, the duties the state machine returns).

mod common;

use ridge_core::control::REFERENCE_S;
use ridge_core::{
    ArxModel, InputMap, IntGram, MapError, Method, Offset, RidgeM, Search, Structure, MAP_KNOTS,
};
use ridge_pump_firmware::event::{
    Event, FaultReason, RejectReason, Residuals, SearchStats, SensorFault, StoredReason,
};
use ridge_pump_firmware::excitation::FlowSteps;
use ridge_pump_firmware::lines::{MapLine, ParsedLine, ScanLine};
use ridge_pump_firmware::persist::{self, PersistError, RECORD_LEN};
use ridge_pump_firmware::selfid::{
    Config, Defaults, SelfIdentification, Settings, State, Tick, DEFAULT_CONFIG, REFERENCE_POLE,
};
use ridge_pump_firmware::setpoint::{Program, DEMO_HOLD_TICKS};
use ridge_pump_firmware::units::{MODEL_SCALE, SAMPLE_RATE_HZ};

use common::Plant;

/// The operating point the state machine must have used for the `k`-th identification
/// attempt: the rounded mean of the readings of the last 50 settle ticks before its scan.
fn settled_y0(log: &[(u16, i16, State)], k: usize) -> i16 {
    let starts: Vec<usize> = (1..log.len())
        .filter(|&i| log[i].2 == State::Scan && log[i - 1].2 == State::Settle)
        .collect();
    let start = starts[k];
    let window = &log[start - 50..start];
    assert!(window.iter().all(|l| l.2 == State::Settle));
    let sum: i32 = window.iter().map(|l| i32::from(l.1)).sum();
    (f64::from(sum) / 50.0).round() as i16
}

/// Counts as the slm text of the report lines.
fn millislm(counts: i16) -> String {
    let m = ridge_pump_firmware::sfm3300::counts_to_millislm(counts);
    format!(
        "{}{}.{:03}",
        if m < 0 { "-" } else { "" },
        m.abs() / 1000,
        m.abs() % 1000
    )
}

/// The number of field `key` in a report line (the firmware's parser).
fn field(line: &str, key: &str) -> f64 {
    ParsedLine::parse(line)
        .num(key)
        .unwrap_or_else(|| panic!("{key} in {line}"))
}

/// The reference plant's steady flow at `duty` (1/10 000), slm: `y = 0.9 y + 10 u − 1` settles
/// at `100 u − 10`.
fn reference_flow(duty: u16) -> f64 {
    100.0 * f64::from(duty) / 10_000.0 - 10.0
}

/// The reference plant's map on the firmware's knot grid (15 % + k · 5.33 %), counts.
fn reference_map() -> InputMap {
    let r = Config::default().records;
    let mut knots = [0i16; MAP_KNOTS];
    for (k, v) in knots.iter_mut().enumerate() {
        let duty = r.map_first + k as u16 * r.map_step;
        *v = (reference_flow(duty) * 120.0).round() as i16;
    }
    InputMap::new(r.map_first, r.map_step, knots).unwrap()
}

/// The flow the Hammerstein model `m` on `map` settles at for `duty`, slm: the map's flow
/// through the dynamics' static gain, plus its intercept's steady part.
fn steady_flow(m: &ArxModel<f32>, map: &InputMap, duty: u16) -> f64 {
    let a1 = 1.0 - m.theta().iter().map(|&t| f64::from(t)).sum::<f64>();
    let b1: f64 = m.phi().iter().map(|&f| f64::from(f)).sum();
    (b1 * f64::from(map.at(duty)) / 120.0 + f64::from(m.intercept())) / a1
}

/// The scan's duties as the settings describe it (`Records`): from the base duty up to the
/// top, down to the bottom and up to the base duty again at the scan rate (each leg ending on
/// its bound), then `lead_in` lags at the base duty.
fn scan_duties(cfg: &Config, lag: u8) -> Vec<u16> {
    let r = cfg.records;
    let base = i32::from(cfg.base_duty);
    let rate = i32::from(r.scan_rate);
    let (top, bottom) = (i32::from(r.scan_high), i32::from(r.scan_low));
    let mut v = Vec::new();
    let mut u = base;
    while u < top {
        u = (u + rate).min(top);
        v.push(u as u16);
    }
    while u > bottom {
        u = (u - rate).max(bottom);
        v.push(u as u16);
    }
    while u < base {
        u = (u + rate).min(base);
        v.push(u as u16);
    }
    v.extend(std::iter::repeat_n(
        cfg.base_duty,
        usize::from(r.lead_in) * usize::from(lag),
    ));
    v
}

/// The duties of a record: its generator rebuilt from the map and lag the lines printed.
fn record_duties(events: &[String], samples: u16, seed: u16) -> Vec<u16> {
    let map = MapLine::parse(events.iter().find(|e| e.starts_with("MAP ")).unwrap())
        .unwrap()
        .map;
    let lag = ScanLine::parse(events.iter().find(|e| e.starts_with("SCAN ")).unwrap())
        .unwrap()
        .lag;
    let r = Config::default().records;
    let mut gen = FlowSteps::new(&map, &r.shape(lag, samples, seed)).unwrap();
    std::iter::from_fn(|| gen.next_step().map(|s| s.0)).collect()
}

fn line(e: &Event) -> String {
    let mut s = heapless::String::<512>::new();
    ufmt::uwrite!(s, "{}", e).unwrap();
    s.as_str().to_owned()
}

/// Runs the closed loop: plant → tick → duty; runs the search when due. Stops after `max`
/// ticks or when `until` holds.
struct Rig {
    sm: SelfIdentification,
    plant: Plant,
    duty: u16,
    ticks: usize,
    events: Vec<String>,
    /// (duty applied, reading, state before the tick) of every tick.
    log: Vec<(u16, i16, State)>,
    pets: usize,
}

impl Rig {
    fn new(cfg: Config, stored: Option<&[u8]>, plant: Plant) -> Self {
        Rig {
            sm: SelfIdentification::new(Box::leak(Box::new(cfg)), stored),
            plant,
            duty: 0,
            ticks: 0,
            events: Vec::new(),
            log: Vec::new(),
            pets: 0,
        }
    }

    fn tick_with(&mut self, reading: Result<i16, SensorFault>) -> Tick {
        let before = self.sm.state();
        let t = self.sm.tick(reading);
        self.log
            .push((self.duty, *reading.as_ref().unwrap_or(&i16::MIN), before));
        self.duty = t.duty;
        self.ticks += 1;
        if let Some(e) = &t.event {
            self.events.push(line(e));
        }
        // As the board loop: the judgement, then the search, after the tick's PWM write; a
        // latched fault stops the pump at once.
        if let Some(e) = self.sm.judge() {
            self.events.push(line(&e));
            if self.sm.fault().is_some() {
                self.duty = 0;
            }
        }
        if self.sm.needs_search() {
            let mut pets = 0;
            if let Some(e) = self.sm.search(|| pets += 1) {
                self.events.push(line(&e));
            }
            self.pets += pets;
        }
        if let Some(e) = self.sm.design(|| {}) {
            self.events.push(line(&e));
            if self.sm.fault().is_some() {
                self.duty = 0;
            }
        }
        t
    }

    fn tick(&mut self) -> Tick {
        let y = self.plant.step(self.duty);
        self.tick_with(Ok(y))
    }

    /// One tick of the state machine alone (no judgement, no search).
    fn tick_without_judgement(&mut self) -> Tick {
        let y = self.plant.step(self.duty);
        let t = self.sm.tick(Ok(y));
        self.duty = t.duty;
        t
    }

    fn run_until(&mut self, max: usize, until: impl Fn(&Self) -> bool) {
        for _ in 0..max {
            if until(self) {
                return;
            }
            self.tick();
        }
        assert!(
            until(self),
            "not reached in {max} ticks: {:#?}",
            self.events
        );
    }

    fn run_to(&mut self, state: State) {
        self.run_until(20_000, |r| r.sm.state() == state);
    }

    fn has_event(&self, prefix: &str) -> bool {
        self.events.iter().any(|e| e.starts_with(prefix))
    }
}

#[test]
fn identifies_the_linear_plant_and_runs() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    rig.run_to(State::Run);
    let ev = &rig.events;
    // Settle 1.5 s, scan, excite 7 s, search, validate 3 s.
    let y0 = millislm(settled_y0(&rig.log, 0));
    let scan = ScanLine::parse(&ev[0]).unwrap();
    // The ramps: 6 500 + 8 000 + 1 500 duty units at 40 a tick, then two lags at the base.
    assert_eq!(scan.samples, 163 + 200 + 38 + 2 * u32::from(scan.lag));
    assert_eq!(
        ev[0],
        format!(
            "SCAN n={} lag={} u0=30.00 y0={y0} attempt=1/3",
            scan.samples, scan.lag
        )
    );
    // The plant's lag: 3 ticks of delay and a 0.095 s time constant, d + τ/Ts ≈ 12.5.
    assert!((11..=15).contains(&scan.lag), "{}", ev[0]);
    assert!(
        ev[1].starts_with("MAP first=15.00 step=5.33 flow="),
        "{ev:#?}"
    );
    assert_eq!(
        ev[2],
        format!("EXCITE flow-steps n=700 u0=30.00 y0={y0} attempt=1/3")
    );
    assert!(
        ev[3].starts_with("ID p=1 q=1 d=3 off=1 theta=0.9"),
        "{ev:#?}"
    );
    assert_eq!(ev[4], "VALIDATE flow-steps n=300", "{ev:#?}");
    assert!(ev[5].starts_with("ACCEPT fit="), "{ev:#?}");
    assert!(ev[5].ends_with(" persist"));
    assert!(
        ev[6].starts_with("CTRL method=pole-placement tau="),
        "{ev:#?}"
    );
    assert_eq!(ev.len(), 7, "{ev:#?}");
    // The plant is the truth. Its map is its steady flow, 100 u − 10 slm: the knots within
    // 0.4 slm (measured ≤ 0.35: the ramps' readings credited one lag back, the linear lag
    // cancels between the rising and the falling side), the two at the scan's turns (15 %,
    // 95 %, beyond the records' 20..85 %) within 3 slm (measured 2.5: the flow does not reach
    // the turn's duty before the ramp comes back).
    let map = *rig.sm.map().unwrap();
    assert_eq!(MapLine::parse(&ev[1]).unwrap().map, map);
    for (k, &v) in map.knots().iter().enumerate() {
        let duty = map.first() + k as u16 * map.step();
        let err = f64::from(v) / 120.0 - reference_flow(duty);
        let tolerance = if k == 0 || k == MAP_KNOTS - 1 {
            3.0
        } else {
            0.4
        };
        assert!(err.abs() < tolerance, "knot {k} at {duty}: {err:+.3} slm");
    }
    // The dynamics from the map's flow: the plant's structure exactly, a static gain of 1; the
    // model's steady flow is the plant's over the records' range.
    let m = *rig.sm.model().unwrap();
    assert_eq!(m.structure(), Structure::new(1, 1, 3).unwrap());
    assert_eq!(m.offset(), Offset::Intercept);
    assert!((m.static_gain() - 1.0).abs() < 0.01, "{m:?}");
    for duty in (2_000..=8_500).step_by(500) {
        let err = steady_flow(&m, &map, duty) - reference_flow(duty);
        assert!(err.abs() < 0.4, "{duty}: {err:+.3} slm {m:?}");
    }
    assert!(m.theta()[0] > 0.895 && m.theta()[0] < 0.905, "{m:?}");
    let fit = rig.sm.fit().unwrap();
    assert!(fit > 95.0, "{fit}");
    // The persisted bytes are the model and its map.
    let bytes = rig.sm.persist_bytes().unwrap();
    assert_eq!(persist::decode(&bytes).unwrap(), (m, map, fit));
    // Run mode: the demo program holds the start flow for 2 s (the controller keeps the duty
    // at the operating point's within the dither), residuals each second at the quantisation
    // level, tracking figures each second half a second later.
    let before = rig.events.len();
    // Until the controller is given the first step ahead of time (the preview).
    let hold = DEMO_HOLD_TICKS - u32::from(rig.sm.preview().unwrap()) - 1;
    for _ in 0..hold {
        let t = rig.tick();
        assert!((2_900..=3_100).contains(&t.duty), "{}", t.duty);
    }
    let after = &rig.events[before..];
    let res: Vec<&String> = after.iter().filter(|e| e.starts_with("RES")).collect();
    assert!(!res.is_empty(), "{after:#?}");
    let track: Vec<&String> = after.iter().filter(|e| e.starts_with("TRACK")).collect();
    assert!(!track.is_empty(), "{after:#?}");
    assert_eq!(res.len() + track.len(), after.len(), "{after:#?}");
    for t in &track {
        assert!((field(t, "sp") - 20.0).abs() < 0.1, "{t}");
        assert!((field(t, "flow") - 20.0).abs() < 0.1, "{t}");
        assert!(field(t, "rms") < 0.05, "{t}");
    }
    for r in &res {
        assert!(r.starts_with("RES rms="), "{r}");
        assert!(field(r, "rms") < 0.02, "{r}"); // the dither: 1.2 counts RMS
                                                // Biased by the map's error at the operating point (≤ 0.11 slm at the knots around
                                                // 30 %) through 1 − θ = 0.1, and its whole counts: measured 0.007.
        assert!(field(r, "mean").abs() < 0.015, "{r}");
        assert!((field(r, "flow") - 20.0).abs() < 0.05, "{r}");
        // A full window, but the predictor's seed samples in the first (m = 3).
        assert!((97.0..=100.0).contains(&field(r, "n")), "{r}");
    }
    assert!(!rig.sm.drift());
}

#[test]
fn ridge_m_bias_vanishes_when_converged() {
    // On the map's flow (slm) the record's input columns carry ~10⁵ slm², so Ridge-M with
    // γ = 1000 shrinks little and converges in a few iterates; converged Ridge-M, or OLS,
    // recovers the plant's dynamics from the map's flow, θ = 0.9 and φ = 0.1 (its gain of 10
    // slm per unit duty over the map's 100), to the map's accuracy.
    for method in [
        Method::RidgeM(RidgeM {
            max_iter: 20_000,
            ..RidgeM::default()
        }),
        Method::Ols,
    ] {
        let mut cfg = Config::default();
        cfg.search.method = method;
        let mut rig = Rig::new(cfg, None, Plant::reference());
        rig.run_to(State::Run);
        let m = rig.sm.model().unwrap();
        assert_eq!(m.structure(), Structure::new(1, 1, 3).unwrap());
        assert!((m.theta()[0] - 0.9).abs() < 2e-3, "{m:?}");
        assert!((m.phi()[0] - 0.1).abs() < 2e-3, "{m:?}");
        assert!(rig.sm.fit().unwrap() > 99.0);
    }
}

#[test]
fn the_record_is_the_exact_statistics_of_the_maps_flow_and_next_reading() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    rig.run_until(20_000, |r| r.sm.state() == State::Excite);
    // Snapshot just before the search: stop when the search is due, without running it.
    let mut gram = None;
    for _ in 0..4000 {
        let y = rig.plant.step(rig.duty);
        let before = rig.sm.state();
        let t = rig.sm.tick(Ok(y));
        rig.log.push((rig.duty, y, before));
        rig.duty = t.duty;
        if rig.sm.needs_search() {
            gram = rig.sm.gram().cloned();
            break;
        }
    }
    let gram = gram.expect("search due");
    // Independent recomputation: every tick that ran in Excite pushed (the map's flow at the
    // duty applied during the interval, the reading at its end) as deviations from (the map's
    // flow at the base duty, the settled mean), all in counts; the map is the MAP line's.
    let map = MapLine::parse(rig.events.iter().find(|e| e.starts_with("MAP ")).unwrap())
        .unwrap()
        .map;
    let y0 = i32::from(settled_y0(&rig.log, 0));
    let v0 = i32::from(map.at(3_000));
    let mut expect = IntGram::new();
    for &(u, y, state) in &rig.log {
        if state == State::Excite {
            expect
                .push(i32::from(map.at(u)) - v0, i32::from(y) - y0)
                .unwrap();
        }
    }
    assert_eq!(expect.len(), 700);
    assert_eq!(gram, expect);
    // The excitation is the record's generator, in order.
    let duties: Vec<u16> = rig
        .log
        .iter()
        .filter(|l| l.2 == State::Excite)
        .map(|l| l.0)
        .collect();
    let r = Config::default().records;
    assert_eq!(duties, record_duties(&rig.events, r.samples, r.seed));
}

/// The scan applies its ramps and lead-in, the validation record its generator (the
/// estimation record's with the complement of its seed): each duty in order.
#[test]
fn the_scan_and_the_validation_record_drive_their_duties() {
    let cfg = Config::default();
    let mut rig = Rig::new(cfg, None, Plant::reference());
    rig.run_until(20_000, |r| r.has_event("ACCEPT"));
    let lag = ScanLine::parse(rig.events.iter().find(|e| e.starts_with("SCAN ")).unwrap())
        .unwrap()
        .lag;
    // The scan's ticks (the state before each tick is Scan from the tick after the one that
    // applied its first duty to the one that applies the record's first): the duties
    // applied during them.
    let scan: Vec<u16> = rig
        .log
        .iter()
        .filter(|l| l.2 == State::Scan)
        .map(|l| l.0)
        .collect();
    assert_eq!(scan, scan_duties(&cfg, lag));
    // The validation record starts one tick after the state does: the tick that ends the
    // search still applied the base duty.
    let validate: Vec<u16> = rig
        .log
        .iter()
        .filter(|l| l.2 == State::Validate)
        .skip(1)
        .map(|l| l.0)
        .collect();
    let r = cfg.records;
    let gen = record_duties(&rig.events, r.validation, !r.seed);
    assert_eq!(validate[..gen.len()], gen[..]);
    assert_ne!(gen, record_duties(&rig.events, r.validation, r.seed));
}

#[test]
fn search_is_only_run_when_due() {
    let mut sm = SelfIdentification::new(&DEFAULT_CONFIG, None);
    assert!(!sm.needs_search());
    assert_eq!(sm.search(|| {}), None);
    assert!(sm.take_search().is_none());
    assert_eq!(sm.state(), State::WaitSensor);
}

#[test]
fn waits_for_the_sensor_then_settles_at_base_duty() {
    let mut sm = SelfIdentification::new(&DEFAULT_CONFIG, None);
    for _ in 0..4 {
        assert_eq!(
            sm.tick(Err(SensorFault::Nack)),
            Tick {
                duty: 0,
                event: None
            }
        );
    }
    assert_eq!(sm.state(), State::WaitSensor);
    let t = sm.tick(Ok(5));
    assert_eq!(t.duty, 3_000);
    assert_eq!(sm.state(), State::Settle);
    // 20 slm with one count of noise (an exact constant would be a frozen sensor): the mean
    // of the last 50 readings is 2 400 counts.
    for k in 0..148 {
        assert_eq!(sm.tick(Ok(2_401 - 2 * (k % 2))).duty, 3_000);
    }
    // The 150th settle tick starts the scan with its first ramp duty (30 % + 0.4 %). The flow
    // responded at once and was settled throughout: the lag is the smallest, 1 tick (two at
    // the base duty after the ramps).
    let t = sm.tick(Ok(2_399));
    assert_eq!(t.duty, 3_040);
    assert_eq!(sm.state(), State::Scan);
    assert_eq!(
        line(&t.event.unwrap()),
        "SCAN n=403 lag=1 u0=30.00 y0=20.000 attempt=1/3"
    );
    assert_eq!(sm.lag(), Some(1));
}

#[test]
fn a_flat_response_is_rejected_as_not_excited_then_faults() {
    // The sensor reads a constant 5 slm whatever the duty (e.g. a blocked duct). With the
    // default settings that is a frozen sensor after 0.5 s (`frozen_sensor_*` tests); here
    // the frozen and no-flow checks are off to reach the excitation check behind them.
    let mut plant = Plant::reference();
    plant.stuck = Some(600);
    let cfg = Config {
        frozen_ticks: 0,
        loss_ticks: 0,
        ..Config::default()
    };
    let mut rig = Rig::new(cfg, None, plant);
    rig.run_to(State::Fault);
    let rejects: Vec<&String> = rig
        .events
        .iter()
        .filter(|e| e.starts_with("REJECT"))
        .collect();
    assert_eq!(
        rejects,
        [
            "REJECT not-excited rms=0.000 attempt=1/3",
            "REJECT not-excited rms=0.000 attempt=2/3",
            "REJECT not-excited rms=0.000 attempt=3/3"
        ]
    );
    // The last rejection (from the search) latches the fault; the next tick stops the pump
    // and reports it.
    assert_eq!(
        rig.events.last().unwrap(),
        "REJECT not-excited rms=0.000 attempt=3/3"
    );
    let t = rig.tick();
    assert_eq!(t.duty, 0);
    assert_eq!(line(&t.event.unwrap()), "FAULT unidentified attempts=3");
    assert_eq!(
        rig.sm.fault(),
        Some(FaultReason::Unidentified { attempts: 3 })
    );
    for _ in 0..100 {
        assert_eq!(rig.tick().duty, 0);
    }
    assert!(rig.sm.model().is_none());
}

#[test]
fn a_noisy_but_unresponsive_flow_is_not_excited() {
    // ±3 counts of noise around 5 slm: RMS well below the 1 slm minimum.
    let mut sm = SelfIdentification::new(&DEFAULT_CONFIG, None);
    let mut duty = 0;
    let mut k: i32 = 0;
    let mut reject = None;
    for _ in 0..10_000 {
        k += 1;
        let y = 600 + ((k * 7919) % 7 - 3) as i16;
        let t = sm.tick(Ok(y));
        duty = t.duty;
        sm.judge();
        if sm.needs_search() {
            reject = sm.search(|| {});
            break;
        }
    }
    let _ = duty;
    match reject {
        Some(Event::Rejected {
            reason: RejectReason::NotExcited { rms },
            attempt: 1,
            attempts: 3,
        }) => assert!(rms > 0.0 && rms < 0.03, "{rms}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(sm.state(), State::Settle);
    assert!(!sm.needs_search());
}

#[test]
fn a_model_that_fails_validation_is_rejected_and_the_next_attempt_succeeds() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    rig.run_to(State::Validate);
    // The plant's gain drops by half during validation: the model must not pass.
    rig.plant.b = 5.0;
    rig.plant.c = -0.5;
    rig.run_until(10_000, |r| r.has_event("REJECT"));
    let reject = rig.events.iter().find(|e| e.starts_with("REJECT")).unwrap();
    assert!(reject.starts_with("REJECT fit="), "{reject}");
    assert!(reject.ends_with("<70.0 attempt=1/3"), "{reject}");
    assert_eq!(rig.sm.state(), State::Settle);
    assert!(rig.sm.model().is_none());
    assert!(rig.sm.persist_bytes().is_none());
    // Second attempt on the changed plant: its scan finds the halved map, 50 u − 5 slm.
    rig.run_to(State::Run);
    let y0 = millislm(settled_y0(&rig.log, 1));
    assert!(rig.has_event(&format!(
        "EXCITE flow-steps n=700 u0=30.00 y0={y0} attempt=2/3"
    )));
    let (m, map) = (rig.sm.model().unwrap(), rig.sm.map().unwrap());
    for duty in [2_000, 5_000, 8_500] {
        let want = reference_flow(duty) / 2.0;
        let got = steady_flow(m, map, duty);
        assert!((got - want).abs() < 0.3, "{duty}: {got} slm, want {want}");
    }
    assert_eq!(rig.sm.attempt(), 2);
}

#[test]
fn a_too_strict_fit_threshold_rejects_every_attempt() {
    let cfg = Config {
        min_fit: 100.0,
        attempts: 2,
        ..Config::default()
    };
    let mut rig = Rig::new(cfg, None, Plant::reference());
    rig.run_to(State::Fault);
    // The rejection at the end of the validation stops the pump in the same tick.
    assert_eq!(rig.duty, 0);
    let rejects = rig
        .events
        .iter()
        .filter(|e| e.starts_with("REJECT fit="))
        .count();
    assert_eq!(rejects, 2);
    let last = rig.events.last().unwrap();
    assert!(last.ends_with("<100.0 attempt=2/2"), "{last}");
    let t = rig.tick();
    assert_eq!(t.duty, 0);
    assert_eq!(line(&t.event.unwrap()), "FAULT unidentified attempts=2");
    assert_latched(&mut rig);
}

/// A rig in each state, for the fault tests.
fn rig_in(state: State) -> Rig {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    match state {
        State::Search => {
            rig.run_until(20_000, |r| {
                r.sm.needs_search() || r.sm.state() == State::Validate
            });
        }
        s => rig.run_to(s),
    }
    rig
}

#[test]
fn consecutive_sensor_errors_stop_the_pump_in_every_state() {
    for state in [
        State::WaitSensor,
        State::Settle,
        State::Scan,
        State::Excite,
        State::Validate,
        State::Run,
    ] {
        for fault in [SensorFault::Nack, SensorFault::Crc, SensorFault::Bus] {
            let mut rig = rig_in(state);
            for k in 1..=4 {
                let t = rig.tick_with(Err(fault));
                assert!(!matches!(t.event, Some(Event::Fault(_))), "{state:?} {k}");
                if state != State::WaitSensor {
                    assert!(t.duty > 0, "{state:?}: bridged error {k} keeps running");
                }
            }
            let t = rig.tick_with(Err(fault));
            assert_eq!(t.duty, 0, "{state:?}");
            assert_eq!(
                t.event,
                Some(Event::Fault(FaultReason::Sensor {
                    error: fault,
                    count: 5
                }))
            );
            assert_latched(&mut rig);
        }
    }
}

/// After a fault: duty 0 and no event for ever, whatever the readings and requests.
fn assert_latched(rig: &mut Rig) {
    assert_eq!(rig.sm.state(), State::Fault);
    rig.sm.request_reidentification();
    assert_eq!(rig.sm.design(|| {}), None);
    for k in 0..300 {
        let reading = if k % 2 == 0 {
            Ok(2_400)
        } else {
            Err(SensorFault::Crc)
        };
        assert_eq!(
            rig.tick_with(reading),
            Tick {
                duty: 0,
                event: None
            }
        );
    }
    assert_eq!(rig.sm.state(), State::Fault);
    assert!(!rig.sm.needs_search());
}

#[test]
fn bridged_sensor_errors_reset_and_count_as_gaps() {
    let mut rig = rig_in(State::Excite);
    // 4 errors, a good reading, 4 errors: no fault.
    for _ in 0..2 {
        for _ in 0..4 {
            rig.tick_with(Err(SensorFault::Nack));
        }
        rig.tick();
    }
    assert_eq!(rig.sm.state(), State::Excite);
    // 3 more gaps (11 > 10) spoil the record.
    for _ in 0..3 {
        rig.tick_with(Err(SensorFault::Crc));
    }
    assert_eq!(rig.events.last().unwrap(), "REJECT gaps=11 attempt=1/3");
    assert_eq!(rig.sm.state(), State::Settle);
}

#[test]
fn flow_out_of_range_stops_the_pump_in_the_same_tick() {
    for state in [
        State::Settle,
        State::Scan,
        State::Excite,
        State::Search,
        State::Validate,
        State::Run,
    ] {
        for (counts, text) in [(30_001i16, "250.008"), (-30_001, "-250.008")] {
            let mut rig = rig_in(state);
            // At the limit is fine.
            let t = rig.tick_with(Ok(if counts > 0 { 30_000 } else { -30_000 }));
            assert!(
                t.duty > 0
                    && t.event
                        .as_ref()
                        .is_none_or(|e| !matches!(e, Event::Fault(_)))
            );
            let t = rig.tick_with(Ok(counts));
            assert_eq!(t.duty, 0, "{state:?}");
            assert_eq!(line(&t.event.unwrap()), format!("FAULT range flow={text}"));
            assert_latched(&mut rig);
        }
    }
}

#[test]
fn a_stalled_pump_is_stopped_after_half_a_second() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    rig.run_to(State::Run);
    for _ in 0..100 {
        rig.tick();
    }
    rig.plant.stuck = Some(10); // 0.083 slm: the rotor is blocked.
                                // The controller raises the duty as fast as its rate limit allows (5 % per tick) up to
                                // its limit; from 40 % on the stall is timed: 0.5 s.
    let mut ticks = 0;
    let fault = loop {
        let t = rig.tick();
        ticks += 1;
        if t.duty == 0 {
            break t.event.expect("the fault is reported");
        }
        assert!(ticks < 60, "no stall fault after {ticks} ticks");
    };
    assert!(ticks >= 50, "{ticks}");
    assert_eq!(line(&fault), "FAULT stall duty=95.00 flow=0.083");
    assert_latched(&mut rig);
}

/// A low flow setpoint held at a duty below the stall duty is not a stall: the controller
/// sits at its lowest duty (15 %, where the reference plant gives 5 slm) for 5 s.
#[test]
fn low_flow_below_the_stall_duty_is_not_a_stall() {
    let mut cfg = Config::default();
    cfg.control.program = Program::Constant(1.0);
    let mut rig = Rig::new(cfg, None, Plant::reference());
    rig.run_to(State::Run);
    for _ in 0..500 {
        rig.tick();
    }
    assert_eq!(rig.duty, cfg.control.duty_min);
    assert!(rig.sm.fault().is_none());
    assert_eq!(rig.sm.state(), State::Run);
}

/// A pump that stops giving flow during the estimation record is stopped: by the stall check
/// at a level of 40 % or more, or by the no-flow check (the settled operating point's flow
/// expected from the base duty up) at a lower one, whichever comes first.
#[test]
fn a_dead_pump_during_the_excitation_is_detected() {
    let mut rig = rig_in(State::Excite);
    rig.plant.stuck = Some(0);
    let from = rig.ticks;
    rig.run_until(3_000, |r| r.sm.state() == State::Fault);
    let last = rig.events.last().unwrap();
    assert!(
        last.starts_with("FAULT stall duty=") || last.starts_with("FAULT noflow duty="),
        "{last}"
    );
    // At most the no-flow check's second after the longest hold below the base duty.
    let r = Config::default().records;
    let longest_hold = usize::from(r.hold_max) * usize::from(r.lag_floor.max(20));
    assert!(
        rig.ticks - from <= longest_hold + 100 + 50,
        "{} ticks",
        rig.ticks - from
    );
    assert_eq!(rig.duty, 0);
}

#[test]
fn a_fault_while_the_search_is_out_makes_its_result_stale() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    let mut job = None;
    for _ in 0..20_000 {
        let y = rig.plant.step(rig.duty);
        rig.duty = rig.sm.tick(Ok(y)).duty;
        // The scan's map.
        rig.sm.judge();
        if rig.sm.needs_search() {
            job = rig.sm.take_search();
            break;
        }
    }
    let job = job.unwrap();
    assert_eq!(job.samples(), 700);
    assert_eq!(rig.sm.state(), State::Search);
    assert!(!rig.sm.needs_search());
    // The timer keeps ticking at the base duty while the main loop searches.
    for _ in 0..10 {
        assert_eq!(rig.tick().duty, 3_000);
    }
    let outcome = job.run(|| {});
    assert!(outcome.result().is_ok());
    let t = rig.tick_with(Ok(31_000));
    assert_eq!(t.duty, 0);
    assert_eq!(rig.sm.finish_search(outcome), None);
    assert_eq!(rig.sm.state(), State::Fault);
}

#[test]
fn the_split_search_gives_the_same_result_as_the_blocking_one() {
    let mut a = Rig::new(Config::default(), None, Plant::reference());
    a.run_to(State::Run);
    let mut b = Rig::new(Config::default(), None, Plant::reference());
    for _ in 0..20_000 {
        let y = b.plant.step(b.duty);
        b.duty = b.sm.tick(Ok(y)).duty;
        if let Some(job) = b.sm.take_search() {
            let e = b.sm.finish_search(job.run(|| {})).unwrap();
            assert!(line(&e).starts_with("ID p=1 q=1 d=3"));
        }
        if let Some(e) = b.sm.judge() {
            assert!(["MAP ", "ACCEPT "].iter().any(|k| line(&e).starts_with(k)));
        }
        if b.sm.state() == State::Run {
            break;
        }
    }
    assert_eq!(a.sm.model(), b.sm.model());
    assert_eq!(a.sm.persist_bytes(), b.sm.persist_bytes());
}

/// The guard a board runs while the state machine cannot tick (the ATmega2560's blocking
/// search) applies the tick's own checks, continuing its counters, and the fault it finds is
/// latched and reported once.
#[test]
fn the_search_guard_checks_like_the_tick_and_its_fault_is_latched_once() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    for _ in 0..20_000 {
        if rig.sm.needs_search() {
            break;
        }
        rig.tick_without_judgement();
        // The scan's map (no validation to judge before the search).
        rig.sm.judge();
    }
    assert!(rig.sm.needs_search());
    // Two sensor errors while the search is due: the guard continues from them.
    rig.sm.tick(Err(SensorFault::Nack));
    rig.sm.tick(Err(SensorFault::Nack));
    let mut guard = rig.sm.guard();
    let mut third = guard;
    assert_eq!(
        third.check(3_000, Err(SensorFault::Nack)),
        Ok(None),
        "third error"
    );
    third.check(3_000, Err(SensorFault::Nack)).unwrap();
    assert!(
        third.check(3_000, Err(SensorFault::Nack)).is_err(),
        "the fifth consecutive error, counting the two before the search"
    );
    assert_eq!(guard.check(3_000, Ok(2_400)), Ok(Some(2_400)));
    // A good reading resets the count: five more errors make the fault, not three.
    for _ in 0..4 {
        assert_eq!(guard.check(3_000, Err(SensorFault::Nack)), Ok(None));
    }
    let reason = guard.check(3_000, Err(SensorFault::Nack)).unwrap_err();
    assert_eq!(
        reason,
        FaultReason::Sensor {
            error: SensorFault::Nack,
            count: 5
        }
    );
    // Range and stall as in `tick`.
    let mut g = rig.sm.guard();
    assert_eq!(
        g.check(3_000, Ok(30_001)),
        Err(FaultReason::FlowRange { counts: 30_001 })
    );
    let mut g = rig.sm.guard();
    for _ in 0..49 {
        assert_eq!(g.check(4_000, Ok(100)), Ok(Some(100)));
    }
    assert_eq!(
        g.check(4_000, Ok(100)),
        Err(FaultReason::Stall {
            duty: 4_000,
            counts: 100
        })
    );
    // The board hands the fault over after the search: duty 0, reported once.
    let event = rig.sm.fault_detected(reason);
    assert_eq!(line(&event), "FAULT sensor=nack n=5");
    assert_eq!(rig.sm.state(), State::Fault);
    assert_eq!(rig.sm.duty(), 0);
    let t = rig.tick();
    assert_eq!((t.duty, t.event), (0, None));
    assert!(!rig.sm.needs_search(), "the pending search is dropped");
}

#[test]
fn the_tick_that_completes_the_validation_only_holds_the_base_duty_until_the_judgement() {
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    rig.run_to(State::Validate);
    // Tick by hand (no judgement) until the record is complete.
    let mut complete = None;
    for _ in 0..4_000 {
        let y = rig.plant.step(rig.duty);
        let t = rig.sm.tick(Ok(y));
        rig.duty = t.duty;
        if rig.sm.needs_judgement() {
            complete = Some(t);
            break;
        }
    }
    let t = complete.expect("validation record complete");
    assert_eq!(t.event, None, "no verdict from the tick itself");
    assert_eq!(t.duty, Config::default().base_duty);
    assert_eq!(rig.sm.state(), State::Validate);
    assert!(rig.sm.model().is_none());
    // Ticks before the judgement hold the base duty and keep the record as it was.
    for _ in 0..3 {
        assert_eq!(rig.tick_without_judgement().duty, 3_000);
    }
    assert!(rig.sm.needs_judgement());
    let verdict = rig.sm.judge().map(|e| line(&e)).unwrap_or_default();
    assert!(verdict.starts_with("ACCEPT fit="), "{verdict}");
    assert!(!rig.sm.needs_judgement());
    assert_eq!(rig.sm.judge(), None, "judged once");
    // The controller design follows a settle phase at the base duty.
    assert_eq!(rig.sm.state(), State::Settle);
    for _ in 0..Config::default().settle_ticks {
        assert_eq!(rig.tick_without_judgement().duty, 3_000);
    }
    assert_eq!(rig.sm.state(), State::Design);
    let ctrl = rig.sm.design(|| {}).map(|e| line(&e)).unwrap_or_default();
    assert!(ctrl.starts_with("CTRL method=pole-placement"), "{ctrl}");
    assert_eq!(rig.sm.state(), State::Run);
    // Bumpless: the first controlled duty is the operating point's, within the dither.
    assert!((2_900..=3_100).contains(&rig.tick().duty));
}

#[test]
fn a_stored_model_skips_identification() {
    let mut first = Rig::new(Config::default(), None, Plant::reference());
    first.run_to(State::Run);
    let bytes = first.sm.persist_bytes().unwrap();
    let model = *first.sm.model().unwrap();

    let map = *first.sm.map().unwrap();
    let mut rig = Rig::new(Config::default(), Some(&bytes), Plant::reference());
    rig.run_to(State::Run);
    assert_eq!(rig.ticks, 150, "settle only");
    assert_eq!(rig.events.len(), 3, "{:#?}", rig.events);
    // The stored map first (the first tick), then the model after the settle phase.
    assert_eq!(MapLine::parse(&rig.events[0]).unwrap().map, map);
    assert!(rig.events[1].starts_with("LOADED p=1 q=1 d=3 off=1 theta=0.9"));
    assert!(rig.events[2].starts_with("CTRL method=pole-placement"));
    assert_eq!(rig.sm.model(), Some(&model));
    assert_eq!(rig.sm.map(), Some(&map));
    assert_eq!(rig.sm.fit(), first.sm.fit());
    // The demo program holds the settled flow for 2 s (less the preview of its first step).
    let hold = DEMO_HOLD_TICKS - u32::from(rig.sm.preview().unwrap()) - 1;
    for _ in 0..hold {
        let duty = rig.tick().duty;
        assert!((2_900..=3_100).contains(&duty), "{duty}");
    }
    let res = rig.events.iter().find(|e| e.starts_with("RES")).unwrap();
    assert!(field(res, "rms") < 0.02, "{:#?}", rig.events);
    // A re-identification request identifies anew, with the lag measured at boot.
    let lag = rig.sm.lag().unwrap();
    rig.sm.request_reidentification();
    rig.run_to(State::Run);
    assert!(rig.has_event(&format!("SCAN n={} lag={lag} ", 401 + 2 * u32::from(lag))));
    assert!(rig.has_event("EXCITE flow-steps n=700 u0=30.00 y0="));
    assert!(rig.has_event("ACCEPT"));
}

/// The setpoint's reference model: `REFERENCE_POLE` is `e^{−Ts/REFERENCE_S}` (std's `exp`
/// here); without a speed given the controller runs it (`ref=` on the CTRL line, the preview
/// its mean delay); with a speed the setpoint response has the regulation pole (`ref` = `α`).
#[test]
fn the_reference_model_sets_the_setpoint_response_unless_a_speed_is_given() {
    let want = (-1.0 / (f64::from(SAMPLE_RATE_HZ) * REFERENCE_S)).exp();
    assert!((f64::from(REFERENCE_POLE) - want).abs() < 1e-7, "{want}");
    let mut first = Rig::new(Config::default(), None, Plant::reference());
    first.run_to(State::Run);
    let bytes = first.sm.persist_bytes().unwrap();
    let ctrl = |cfg: Config| {
        let mut rig = Rig::new(cfg, Some(&bytes), Plant::reference());
        rig.run_to(State::Run);
        let ctrl = rig
            .events
            .iter()
            .find(|e| e.starts_with("CTRL"))
            .unwrap()
            .clone();
        (ctrl, rig.sm.preview().unwrap())
    };
    let (default, preview) = ctrl(Config::default());
    assert!((field(&default, "ref") - want).abs() < 6e-4, "{default}");
    // The mean delay of q^{−d−1} B/B(1) (one φ, d = 3: 4 samples) plus γ / (1 − γ).
    let mean = 4.0 + want / (1.0 - want);
    assert_eq!(f64::from(preview), mean.round(), "{default}");
    let mut cfg = Config::default();
    cfg.control.tau = Some(0.05);
    let (given, preview) = ctrl(cfg);
    let alpha = (-0.01f64 / 0.05).exp();
    assert!((field(&given, "ref") - alpha).abs() < 6e-4, "{given}");
    assert!(given.contains(&format!(" poles={alpha:.3},")), "{given}");
    assert_eq!(
        f64::from(preview),
        (4.0 + alpha / (1.0 - alpha)).round(),
        "{given}"
    );
}

#[test]
fn corrupt_stored_bytes_are_reported_and_identification_runs() {
    let model = ArxModel::new(&[0.9], &[0.1], 3, Offset::Intercept, 0.0).unwrap();
    let good = persist::encode(&model, &reference_map(), 99.5);
    let mut cases: Vec<(Vec<u8>, &str)> = Vec::new();
    for byte in 0..RECORD_LEN {
        for bit in 0..8 {
            let mut bad = good.to_vec();
            bad[byte] ^= 1 << bit;
            let reason = match byte {
                0..=3 => "magic",
                4 => "version",
                _ => "crc",
            };
            cases.push((bad, reason));
        }
    }
    cases.push((good[..RECORD_LEN - 1].to_vec(), "length"));
    cases.push((Vec::new(), "length"));
    cases.push((vec![0xFF; RECORD_LEN], "magic"));
    let mut old = good;
    old[4] = 0;
    let crc = persist::crc32(&old[..RECORD_LEN - 4]);
    old[RECORD_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
    cases.push((old.to_vec(), "version"));

    for (bytes, reason) in &cases {
        let mut sm = SelfIdentification::new(&DEFAULT_CONFIG, Some(bytes));
        assert!(sm.model().is_none());
        let t = sm.tick(Ok(0));
        assert_eq!(line(&t.event.unwrap()), format!("STORED-REJECTED {reason}"));
        // 20 slm with one count of noise (an exact constant would be a frozen sensor).
        for k in 0..148 {
            assert_eq!(sm.tick(Ok(2_399 + 2 * (k % 2))).event, None);
        }
        let t = sm.tick(Ok(2_400));
        assert_eq!(sm.state(), State::Scan, "{reason}");
        assert!(matches!(t.event, Some(Event::Scan { attempt: 1, .. })));
    }
    // The good record loads; its map is reported first.
    let mut sm = SelfIdentification::new(&DEFAULT_CONFIG, Some(&good));
    assert_eq!(sm.model(), Some(&model));
    assert_eq!(sm.map(), Some(&reference_map()));
    assert_eq!(sm.tick(Ok(0)).event, Some(Event::Map(reference_map())));
    let _ = PersistError::Crc;
}

#[test]
fn drift_is_raised_after_k_seconds_above_the_limit() {
    let mut cfg = Config::default();
    cfg.control.program = Program::Hold;
    let mut rig = Rig::new(cfg, None, Plant::reference());
    rig.run_to(State::Run);
    for _ in 0..500 {
        rig.tick();
    }
    assert!(!rig.sm.drift());
    let before = rig.events.len();
    // The pump loses 60 % of its gain (e.g. a leak upstream of the sensor): the controller
    // makes up for it (60 % duty for the 20 slm), the monitor sees the model is wrong.
    rig.plant.b = 4.0;
    rig.plant.c = -0.4;
    for _ in 0..600 {
        rig.tick();
    }
    assert!((5_800..=6_200).contains(&rig.duty), "{}", rig.duty);
    let after: Vec<&String> = rig.events[before..].iter().collect();
    let drift = after.iter().position(|e| e.starts_with("DRIFT")).unwrap();
    assert!(after[drift].ends_with("s=3 reid=0"), "{after:#?}");
    assert_eq!(after.iter().filter(|e| e.starts_with("DRIFT")).count(), 1);
    assert!(rig.sm.drift());
    assert_eq!(rig.sm.state(), State::Run);
}

#[test]
fn drift_can_trigger_reidentification() {
    let mut cfg = Config::default();
    cfg.monitor.reidentify = true;
    let mut rig = Rig::new(cfg, None, Plant::reference());
    rig.run_to(State::Run);
    let old = *rig.sm.model().unwrap();
    rig.plant.b = 4.0;
    rig.plant.c = -0.4;
    rig.run_until(2_000, |r| r.has_event("DRIFT"));
    assert!(rig.events.last().unwrap().ends_with("s=3 reid=1"));
    assert_eq!(rig.sm.state(), State::Settle);
    assert!(rig.sm.drift());
    // The old model stays until the new one is accepted.
    assert_eq!(rig.sm.model(), Some(&old));
    rig.run_to(State::Run);
    // The new model is the changed plant's: 40 u − 4 slm.
    let (new, map) = (rig.sm.model().unwrap(), rig.sm.map().unwrap());
    for duty in [3_000, 6_000, 8_500] {
        let want = 0.4 * reference_flow(duty);
        let got = steady_flow(new, map, duty);
        assert!((got - want).abs() < 0.3, "{duty}: {got} slm, want {want}");
    }
    assert!(!rig.sm.drift());
}

/// An unreachable setpoint (the reference plant gives 85 slm at 95 %): the duty stays at the
/// controller's limit and the tracking alarm is raised after its 0.5 s; a reachable one again
/// clears it.
#[test]
fn unreachable_setpoint_saturates_and_raises_the_tracking_alarm() {
    let mut cfg = Config::default();
    cfg.control.program = Program::Constant(200.0);
    let mut rig = Rig::new(cfg, None, Plant::reference());
    rig.run_to(State::Run);
    let before = rig.events.len();
    for _ in 0..200 {
        rig.tick();
    }
    assert_eq!(rig.duty, cfg.control.duty_max);
    assert!(rig.sm.tracking_alarm());
    let alarms: Vec<&String> = rig.events[before..]
        .iter()
        .filter(|e| e.starts_with("ALARM"))
        .collect();
    assert_eq!(alarms.len(), 1, "{:#?}", rig.events);
    assert!(alarms[0].starts_with("ALARM track err=11"), "{}", alarms[0]);
    assert!(alarms[0].ends_with(" s=0.50"), "{}", alarms[0]);
}

#[test]
fn event_lines_are_as_documented() {
    let model =
        ArxModel::new(&[0.935, -0.125], &[6.5, 0.25], 3, Offset::Intercept, -0.125).unwrap();
    let cases: Vec<(Event, &str)> = vec![
        (
            Event::StoredRejected(StoredReason::Record(PersistError::Crc)),
            "STORED-REJECTED crc",
        ),
        (
            Event::Loaded { model, fit: 87.25 },
            "LOADED p=2 q=2 d=3 off=1 theta=0.935000,-0.125000 phi=6.500000,0.250000 c=-0.125000 fit=87.3",
        ),
        (
            Event::Scan {
                samples: 441,
                lag: 20,
                u0: 3_000,
                y0: 2_287,
                attempt: 1,
                attempts: 3,
            },
            "SCAN n=441 lag=20 u0=30.00 y0=19.058 attempt=1/3",
        ),
        (
            Event::Map(
                InputMap::new(
                    1_500,
                    533,
                    [
                        15, 759, 1_007, 1_603, 2_400, 3_600, 4_320, 5_280, 6_000, 7_200, 8_400,
                        9_600, 10_800, 12_000, 13_200, 15_000,
                    ],
                )
                .unwrap(),
            ),
            "MAP first=15.00 step=5.33 flow=0.125,6.325,8.392,13.358,20.000,30.000,36.000,44.000,\
             50.000,60.000,70.000,80.000,90.000,100.000,110.000,125.000",
        ),
        (
            Event::Excite {
                samples: 700,
                u0: 3_000,
                y0: 2_287,
                attempt: 1,
                attempts: 3,
            },
            "EXCITE flow-steps n=700 u0=30.00 y0=19.058 attempt=1/3",
        ),
        (
            Event::Identified {
                model,
                stats: SearchStats {
                    score: -1234.5,
                    candidates: 252,
                    evaluated: 14,
                    skipped: 0,
                    iterations: 200,
                    samples: 3000,
                },
            },
            "ID p=2 q=2 d=3 off=1 theta=0.935000,-0.125000 phi=6.500000,0.250000 c=-0.125000 score=-1234.5 eval=14/252 skip=0 iters=200",
        ),
        (Event::Validate { samples: 300 }, "VALIDATE flow-steps n=300"),
        (
            Event::Accepted {
                fit: 90.875,
                rmse: 3.25,
                one_step: 2.0625,
                samples: 2994,
            },
            "ACCEPT fit=90.9 rmse=3.250 one=2.063 n=2994 persist",
        ),
        (
            Event::Rejected {
                reason: RejectReason::Fit {
                    fit: 42.125,
                    min: 70.0,
                },
                attempt: 1,
                attempts: 3,
            },
            "REJECT fit=42.1<70.0 attempt=1/3",
        ),
        (
            Event::Rejected {
                reason: RejectReason::NotExcited { rms: 0.0125 },
                attempt: 2,
                attempts: 3,
            },
            "REJECT not-excited rms=0.013 attempt=2/3",
        ),
        (
            Event::Rejected {
                reason: RejectReason::Search(ridge_core::Error::NoCandidate),
                attempt: 3,
                attempts: 3,
            },
            "REJECT search=no-candidate attempt=3/3",
        ),
        (
            Event::Rejected {
                reason: RejectReason::Map(MapError::NotIncreasing),
                attempt: 1,
                attempts: 3,
            },
            "REJECT map=not-increasing attempt=1/3",
        ),
        (
            Event::Rejected {
                reason: RejectReason::NonFinite,
                attempt: 1,
                attempts: 1,
            },
            "REJECT nonfinite attempt=1/1",
        ),
        (
            Event::Rejected {
                reason: RejectReason::SensorGaps { gaps: 11 },
                attempt: 1,
                attempts: 3,
            },
            "REJECT gaps=11 attempt=1/3",
        ),
        (
            Event::Residual(Residuals {
                // 64 samples (an exact reciprocal): RMS exactly 0.8125, mean −1/64.
                sum_sq: 0.8125 * 0.8125 * 64.0,
                sum: -1.0,
                sum_flow: 50.125 * 64.0,
                samples: 64,
            }),
            "RES rms=0.813 mean=-0.016 flow=50.125 n=64",
        ),
        (
            Event::Drift {
                residuals: Residuals {
                    sum_sq: 3.25 * 3.25 * 64.0,
                    sum: -3.0 * 64.0,
                    sum_flow: 35.375 * 64.0,
                    samples: 64,
                },
                seconds: 3,
                reidentify: false,
            },
            "DRIFT rms=3.250 mean=-3.000 flow=35.375 s=3 reid=0",
        ),
        (
            Event::Fault(FaultReason::Sensor {
                error: SensorFault::Crc,
                count: 5,
            }),
            "FAULT sensor=crc n=5",
        ),
        (
            Event::Fault(FaultReason::FlowRange { counts: -31_245 }),
            "FAULT range flow=-260.375",
        ),
        (
            Event::Fault(FaultReason::Stall {
                duty: 4_500,
                counts: 15,
            }),
            "FAULT stall duty=45.00 flow=0.125",
        ),
        (
            Event::Fault(FaultReason::Unidentified { attempts: 3 }),
            "FAULT unidentified attempts=3",
        ),
    ];
    for (event, text) in cases {
        assert_eq!(line(&event), text);
        assert_eq!(event.persist(), text.starts_with("ACCEPT"));
    }
}

#[test]
fn sensor_fault_from_driver_errors() {
    use ridge_pump_firmware::sfm3300::Error;
    assert_eq!(SensorFault::from(Error::<()>::NotReady), SensorFault::Nack);
    assert_eq!(SensorFault::from(Error::<()>::Crc), SensorFault::Crc);
    assert_eq!(SensorFault::from(Error::I2c(())), SensorFault::Bus);
}

#[test]
fn host_search_on_the_same_record_agrees() {
    // The state machine's f32 result against ridge-core's f64 search on its own record.
    let mut rig = Rig::new(Config::default(), None, Plant::reference());
    rig.run_to(State::Run);
    let y0 = i32::from(settled_y0(&rig.log, 0));
    let map = *rig.sm.map().unwrap();
    let v0 = i32::from(map.at(3_000));
    let mut gram = IntGram::new();
    for &(u, y, state) in &rig.log {
        if state == State::Excite {
            gram.push(i32::from(map.at(u)) - v0, i32::from(y) - y0)
                .unwrap();
        }
    }
    let search = Search::<f64> {
        offset: Offset::Intercept,
        ..Search::default()
    };
    let sel = search
        .run(&gram.normal::<f64>(MODEL_SCALE).unwrap(), None)
        .unwrap();
    let m64 = sel.fit.model();
    let m32 = rig.sm.model().unwrap();
    assert_eq!(m64.structure(), m32.structure());
    assert!((m64.theta()[0] - f64::from(m32.theta()[0])).abs() < 1e-4);
    assert!((m64.phi()[0] - f64::from(m32.phi()[0])).abs() < 1e-3 * m64.phi()[0].abs());
}

/// Every tick of `sm` on the reference plant as the board loop runs it (tick, judgement,
/// search, design): `duty event` per tick, for `ticks` ticks.
fn trace<S: Settings>(mut sm: SelfIdentification<S>, ticks: usize) -> Vec<String> {
    let mut plant = Plant::reference();
    let mut duty = 0;
    let mut out = Vec::with_capacity(ticks);
    for _ in 0..ticks {
        let t = sm.tick(Ok(plant.step(duty)));
        duty = t.duty;
        let mut row = format!("{duty}");
        let mut events = vec![t.event];
        events.push(sm.judge());
        if sm.needs_search() {
            events.push(sm.search(|| {}));
        }
        events.push(sm.design(|| {}));
        for e in events.into_iter().flatten() {
            row.push(' ');
            row.push_str(&line(&e));
        }
        if sm.fault().is_some() {
            duty = 0;
        }
        out.push(row);
    }
    out
}

/// The board images' compile-time settings ([`Defaults`]) behave exactly as the run-time
/// `&DEFAULT_CONFIG` the host tests use: the same duty and the same report lines at every tick,
/// from power-up through identification, design and 30 s of run mode, and from a stored
/// record. (On the ATmega2560 the folded settings are what the simavr tests run.)
#[test]
fn defaults_behave_as_the_default_config() {
    let ticks = 6_000;
    let runtime = trace(SelfIdentification::new(&DEFAULT_CONFIG, None), ticks);
    let fixed = trace(SelfIdentification::new(Defaults, None), ticks);
    let ctrl = runtime.iter().position(|r| r.contains(" CTRL "));
    assert!(
        ctrl.is_some_and(|k| k + 3_000 < ticks),
        "no 30 s of run mode: {:?}",
        runtime
            .iter()
            .filter(|r| r.contains(' '))
            .collect::<Vec<_>>()
    );
    for (k, (a, b)) in runtime.iter().zip(&fixed).enumerate() {
        assert_eq!(a, b, "tick {k}");
    }

    let model = ArxModel::new(&[0.9f32], &[0.1], 3, Offset::Intercept, 0.0).unwrap();
    let record = persist::encode(&model, &reference_map(), 90.0);
    let runtime = trace(
        SelfIdentification::new(&DEFAULT_CONFIG, Some(&record)),
        1_000,
    );
    let fixed = trace(SelfIdentification::new(Defaults, Some(&record)), 1_000);
    assert!(
        runtime.iter().any(|r| r.contains(" LOADED ")),
        "{runtime:?}"
    );
    assert_eq!(runtime, fixed);
}
