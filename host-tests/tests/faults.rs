//! The frozen-sensor and no-flow checks of the firmware's state machine against the pump-sim
//! plant (blower + SFM3300 noise model, optionally a test lung) in closed loop, with the faults
//! injected into the simulated hardware:
//! - *frozen sensor*: from tick T on the sensor returns the word it returned last;
//! - *dead PWM line*: from tick T on the blower sees duty 0 whatever is commanded.
//!
//! The search and the controller design run the blocking way of the ATmega2560: meanwhile a copy
//! of the tick's checks (`SelfIdentification::guard`) reads the sensor at every tick boundary
//! with the pump holding its duty, as the loop's keepalive does (`firmware/src/app/jobs.rs`),
//! and a fault it finds is handed to `SelfIdentification::fault_detected` (the keepalive stops
//! the pump itself).
//!
//! The bounds asserted are the documented ones (`Config::frozen_ticks`, `Config::loss_ticks`,
//! `Config::settle_ticks`), with the blower's coast-down computed from its parameters; the
//! healthy runs (every blower, open outlet and test lungs, several noise seeds, the demo
//! program's holds, steps and breaths) must raise no fault at all.

use pump_sim::{LungParams, PumpParams, Rig, Sfm3300Params};
use ridge_pump_firmware::event::{Event, FaultReason};
use ridge_pump_firmware::selfid::{Config, SelfIdentification, State};
use ridge_pump_firmware::sfm3300::raw_to_counts;

/// Tick boundaries the keepalive handles while the blocking search runs (the ATmega2560's search
/// takes several seconds) and while the design runs (tens of milliseconds).
const SEARCH_TICKS: usize = 300;
const DESIGN_TICKS: usize = 6;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Inject {
    Freeze,
    DeadPwm,
}

/// A fault the state machine (or the keepalive) latched: the tick it was raised in, the reason
/// and the duty applied from that tick on.
#[derive(Debug, Clone, Copy)]
struct Raised {
    tick: usize,
    reason: FaultReason,
    duty: u16,
}

struct Loop {
    sm: SelfIdentification,
    rig: Rig,
    /// Duty the firmware applies to the PWM, 1/10 000.
    duty: u16,
    /// The last word the sensor returned, and the frozen one.
    last_raw: u16,
    frozen: Option<u16>,
    /// The blower sees duty 0.
    dead: bool,
    /// Inject this at the first tick boundary of the next blocking job.
    in_watch: Option<Inject>,
    ticks: usize,
    raised: Option<Raised>,
    /// When the fault was injected (tick count).
    injected: Option<usize>,
    /// Ticks that started in run mode, for the healthy runs.
    run_ticks: usize,
}

impl Loop {
    fn new(pump: PumpParams, lung: Option<LungParams>, seed: u64) -> Self {
        Self::with(Config::default(), pump, lung, seed)
    }

    fn with(cfg: Config, pump: PumpParams, lung: Option<LungParams>, seed: u64) -> Self {
        let rig = Rig::new(pump, Sfm3300Params::default(), seed);
        let rig = match lung {
            Some(l) => rig.with_lung(l),
            None => rig,
        };
        Loop {
            sm: SelfIdentification::new(Box::leak(Box::new(cfg)), None),
            rig,
            duty: 0,
            last_raw: 0,
            frozen: None,
            dead: false,
            in_watch: None,
            ticks: 0,
            raised: None,
            injected: None,
            run_ticks: 0,
        }
    }

    fn inject(&mut self, what: Inject) {
        match what {
            Inject::Freeze => self.frozen = Some(self.last_raw),
            Inject::DeadPwm => self.dead = true,
        }
        self.injected = Some(self.ticks);
    }

    /// One 10 ms interval of the plant at the PWM's duty; the sensor's reading at its end.
    fn sense(&mut self) -> i16 {
        let plant_duty = if self.dead { 0 } else { self.duty };
        let raw = self.rig.step(plant_duty);
        let raw = self.frozen.unwrap_or(raw);
        self.last_raw = raw;
        self.ticks += 1;
        raw_to_counts(raw)
    }

    fn raise(&mut self, reason: FaultReason, duty: u16) {
        if self.raised.is_none() {
            self.raised = Some(Raised {
                tick: self.ticks,
                reason,
                duty,
            });
        }
    }

    fn tick(&mut self) {
        let c = self.sense();
        if self.sm.state() == State::Run {
            self.run_ticks += 1;
        }
        let t = self.sm.tick(Ok(c));
        self.duty = t.duty;
        if let Some(Event::Fault(r)) = t.event {
            self.raise(r, t.duty);
        }
        if self.sm.judge().is_some() {
            if let Some(r) = self.sm.fault() {
                self.duty = 0;
                self.raise(r, 0);
            }
        }
        if self.sm.needs_search() && self.keepalive(SEARCH_TICKS) {
            let _ = self.sm.search(|| {});
        }
        if self.sm.needs_design() && self.keepalive(DESIGN_TICKS) {
            let _ = self.sm.design(|| {});
            if let Some(r) = self.sm.fault() {
                self.duty = 0;
                self.raise(r, 0);
            }
        }
    }

    /// The blocking job's tick boundaries, as the loop's keepalive: the pump holds its duty, a
    /// copy of the checks reads the sensor. `false` when it found a fault (latched, pump
    /// stopped).
    fn keepalive(&mut self, ticks: usize) -> bool {
        let mut guard = self.sm.guard();
        let applied = self.duty;
        for _ in 0..ticks {
            if let Some(what) = self.in_watch.take() {
                self.inject(what);
            }
            let c = self.sense();
            if let Err(reason) = guard.check(applied, Ok(c)) {
                self.duty = 0;
                self.sm.fault_detected(reason);
                self.raise(reason, 0);
                return false;
            }
        }
        self.sm.resume_guard(&guard);
        true
    }

    fn run_until(&mut self, max: usize, until: impl Fn(&Self) -> bool) {
        for _ in 0..max {
            if until(self) {
                return;
            }
            self.tick();
        }
        assert!(until(self), "not reached in {max} ticks: {:?}", self.raised);
    }

    /// Ticks from the injection to the fault, and the fault.
    fn detection(&mut self, max: usize) -> (usize, Raised) {
        self.run_until(max, |l| l.raised.is_some());
        let r = self.raised.unwrap();
        (r.tick - self.injected.expect("injected"), r)
    }
}

fn pumps() -> [(&'static str, PumpParams); 3] {
    [
        ("default", PumpParams::default()),
        ("small", PumpParams::small()),
        ("sluggish", PumpParams::sluggish()),
    ]
}

fn outlets() -> [(&'static str, Option<LungParams>); 3] {
    [
        ("open", None),
        ("adult", Some(LungParams::adult())),
        ("stiff", Some(LungParams::stiff())),
    ]
}

/// Where a fault is injected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Where {
    /// 1.5 s into the first settle phase (the pump at the base duty).
    Settle,
    /// 10 s into the estimation record.
    Excite,
    /// At the first tick boundary of the blocking search.
    Search,
    /// 10 s into the validation record.
    Validate,
    /// At the first tick boundary of the blocking controller design.
    Design,
    /// 5 s into run mode (the demo program).
    Run,
}

const EVERY_STATE: [Where; 6] = [
    Where::Settle,
    Where::Excite,
    Where::Search,
    Where::Validate,
    Where::Design,
    Where::Run,
];

/// Runs the healthy loop to `at`, injects `what` there.
fn inject_at(lp: &mut Loop, at: Where, what: Inject) {
    let into = |lp: &mut Loop, state: State, ticks: usize| {
        lp.run_until(30_000, |l| l.sm.state() == state);
        for _ in 0..ticks {
            lp.tick();
        }
        assert_eq!(lp.sm.state(), state, "{at:?}");
        assert!(lp.raised.is_none(), "healthy until {at:?}: {:?}", lp.raised);
        lp.inject(what);
    };
    match at {
        Where::Settle => into(lp, State::Settle, 150),
        Where::Excite => into(lp, State::Excite, 1_000),
        Where::Validate => into(lp, State::Validate, 1_000),
        Where::Run => into(lp, State::Run, 500),
        Where::Search => {
            lp.run_until(30_000, |l| l.sm.state() == State::Excite);
            lp.in_watch = Some(what);
            lp.run_until(30_000, |l| l.injected.is_some());
        }
        Where::Design => {
            lp.run_until(30_000, |l| l.sm.state() == State::Validate);
            lp.run_until(30_000, |l| l.sm.state() != State::Validate);
            lp.in_watch = Some(what);
            lp.run_until(30_000, |l| l.injected.is_some());
        }
    }
}

/// Ticks a blower with `p` needs after its PWM line died for its flow to fall from the
/// largest it gives (at the controller's 95 % duty limit, the records' maximum) below a
/// quarter of the operating point's flow at the 30 % base duty (with 20 % margin for the
/// settled mean's noise): the transport delay and the coast-down `speed = e^(−t/τ_down)`,
/// `flow ∝ speed^exponent`. The no-flow check's expectation is at least the operating point's
/// flow wherever it checks before a model is in use, and at least the flow before the fault
/// in run mode (the controller only raises the duty when the flow goes).
fn coast_down_ticks(p: &PumpParams) -> usize {
    let from = p.steady_state_flow(0.95);
    let to = p.steady_state_flow(0.30) / 4.0 * 0.8;
    let t = p.tau_down_s * (from / to).ln() / p.flow_exponent;
    p.delay_samples + (t / p.ts_s).ceil() as usize + 1
}

#[test]
fn a_frozen_sensor_is_detected_in_every_state_within_frozen_ticks() {
    let limit = usize::from(Config::default().frozen_ticks);
    let mut worst = 0;
    for (name, pump) in pumps() {
        for at in EVERY_STATE {
            let mut lp = Loop::new(pump.clone(), None, 11);
            inject_at(&mut lp, at, Inject::Freeze);
            let (ticks, r) = lp.detection(limit + 10);
            // The frozen word was already read once before the injection: `limit − 1` more
            // identical readings complete the count.
            assert!(ticks <= limit, "{name} {at:?}: {ticks} ticks");
            assert!(
                matches!(r.reason, FaultReason::Frozen { .. }),
                "{name} {at:?}: {r:?}"
            );
            // The pump is stopped in the tick that raised it.
            assert_eq!(r.duty, 0, "{name} {at:?}");
            assert_eq!(lp.duty, 0);
            assert_eq!(lp.sm.state(), State::Fault);
            worst = worst.max(ticks);
        }
    }
    println!("frozen sensor: detected after at most {worst} ticks");
}

/// The no-flow bound of a dead PWM line injected at `at`, ticks after the injection: the
/// coast-down plus `loss_ticks` checked ticks. During the records only ticks at or above the
/// base duty are checked: their count follows from the record's duty sequence (independent of
/// the firmware's state), `record_tick` being the record's tick at the injection.
fn loss_bound(pump: &PumpParams, at: Where, record_tick: usize) -> usize {
    let cfg = Config::default();
    let loss = usize::from(cfg.loss_ticks);
    let coast = coast_down_ticks(pump);
    match at {
        Where::Excite | Where::Validate => {
            let rec = if at == Where::Excite {
                cfg.excitation
            } else {
                cfg.validation
            };
            let duties: Vec<u16> = rec.generator().collect();
            let mut checked = 0;
            let mut k = record_tick + coast;
            // Past the record's end the pump holds the base duty: every tick is checked.
            while checked < loss {
                if duties.get(k).is_none_or(|&d| d >= cfg.base_duty) {
                    checked += 1;
                }
                k += 1;
            }
            k - record_tick + 1
        }
        _ => coast + loss + 1,
    }
}

#[test]
fn a_dead_pwm_line_is_detected_in_every_state_within_the_bound() {
    let cfg = Config::default();
    let mut report = Vec::new();
    for (name, pump) in pumps() {
        for at in EVERY_STATE {
            let mut lp = Loop::new(pump.clone(), None, 5);
            inject_at(&mut lp, at, Inject::DeadPwm);
            let bound = match at {
                // The first settle phase expects nothing yet (and its operating point is
                // then near zero): the stall check in the excitation that follows.
                Where::Settle => 50 + stall_bound(cfg.excitation, 0),
                Where::Excite | Where::Validate => loss_bound(&pump, at, 1_000),
                _ => loss_bound(&pump, at, 0),
            };
            let (ticks, r) = lp.detection(bound + 50);
            assert!(
                ticks <= bound,
                "{name} {at:?}: {ticks} > {bound} ticks, {r:?}"
            );
            // A duty of 40 % or more trips the older stall check first; below it the no-flow
            // check.
            match r.reason {
                FaultReason::NoFlow { duty, .. } => {
                    assert!(duty < cfg.stall_duty || at == Where::Run)
                }
                FaultReason::Stall { .. } => {}
                other => panic!("{name} {at:?}: {other:?}"),
            }
            assert_eq!(r.duty, 0, "{name} {at:?}");
            assert_eq!(lp.duty, 0);
            report.push(format!(
                "{name} {at:?}: {ticks}/{bound} ticks {:?}",
                r.reason
            ));
        }
    }
    println!("{}", report.join("\n"));
}

/// The case: run mode holding a flow the blower gives at 30 % duty, the controller's
/// duty limit at 35 % so that it cannot reach the 40 % stall duty when the flow goes: the
/// model's static gain says what flow to expect, and the no-flow check stops the pump.
#[test]
fn a_dead_pwm_line_below_the_stall_duty_is_detected_in_run_mode() {
    for (name, pump) in pumps() {
        let mut cfg = Config::default();
        cfg.control.duty_max = 3_500;
        let flow = pump.steady_state_flow(0.30) as f32;
        cfg.control.program = ridge_pump_firmware::setpoint::Program::Constant(flow);
        let mut lp = Loop::with(cfg, pump.clone(), None, 3);
        lp.run_until(30_000, |l| l.sm.state() == State::Run);
        for _ in 0..500 {
            lp.tick();
        }
        assert!(lp.raised.is_none(), "{name}: {:?}", lp.raised);
        lp.inject(Inject::DeadPwm);
        let bound = loss_bound(&pump, Where::Run, 0);
        let (ticks, r) = lp.detection(bound + 50);
        assert!(ticks <= bound, "{name}: {ticks} > {bound}");
        match r.reason {
            FaultReason::NoFlow { duty, .. } => assert!(duty <= 3_500, "{name} {duty}"),
            other => panic!("{name}: {other:?}"),
        }
        assert_eq!(r.duty, 0);
        println!("{name}: no flow at <= 35 % detected after {ticks} ticks (bound {bound})");
    }
}

/// A dead PWM line from power-up: nothing is expected before the first operating point (a
/// stiff test lung gives less than 1 slm at the 30 % base duty, so the settled flow says
/// nothing), and that operating point is near zero; the excitation's first stretch at 40 % or
/// more trips the stall check, instead of three rejected records (about 100 s).
#[test]
fn a_dead_pwm_line_from_power_up_is_a_stall_in_the_first_excitation() {
    let cfg = Config::default();
    for (name, pump) in pumps() {
        let mut lp = Loop::new(pump, None, 9);
        lp.inject(Inject::DeadPwm);
        // One wait tick, the settle phase, then the record up to its first stall.
        let bound = 1 + usize::from(cfg.settle_ticks) + stall_bound(cfg.excitation, 0);
        let (ticks, r) = lp.detection(bound + 50);
        assert!(ticks <= bound, "{name}: {ticks} > {bound}");
        assert!(
            matches!(r.reason, FaultReason::Stall { .. }),
            "{name}: {r:?}"
        );
        assert_eq!(r.duty, 0);
        println!("{name}: dead from power-up, stall after {ticks} ticks (bound {bound})");
    }
}

/// Ticks from the record's tick `from` until its duty sequence (independent of the firmware's
/// state) completes `stall_ticks` consecutive ticks at the stall duty or more, plus one for
/// the applied duty's lag.
fn stall_bound(rec: ridge_pump_firmware::excitation::Record, from: usize) -> usize {
    let cfg = Config::default();
    let duties: Vec<u16> = rec.generator().collect();
    let mut run = 0;
    for (k, &d) in duties.iter().enumerate().skip(from) {
        run = if d >= cfg.stall_duty { run + 1 } else { 0 };
        if run >= usize::from(cfg.stall_ticks) {
            return k - from + 2;
        }
    }
    panic!("the record never holds the stall duty for the stall time");
}

/// The healthy plants, several noise seeds each: identification, design and 40 s of the demo
/// program (hold, setpoint steps, breaths), with no fault.
fn healthy(pump_name: &str, seeds: &[u64]) {
    let pump = pumps().into_iter().find(|p| p.0 == pump_name).unwrap().1;
    let mut runs = 0;
    for (outlet, lung) in outlets() {
        for &seed in seeds {
            let mut lp = Loop::new(pump.clone(), lung.clone(), seed);
            lp.run_until(40_000, |l| l.sm.state() == State::Run || l.raised.is_some());
            assert!(
                lp.raised.is_none(),
                "{pump_name} {outlet} seed {seed}: {:?}",
                lp.raised
            );
            for _ in 0..4_000 {
                lp.tick();
            }
            assert!(
                lp.raised.is_none(),
                "{pump_name} {outlet} seed {seed}: {:?}",
                lp.raised
            );
            assert_eq!(
                lp.sm.state(),
                State::Run,
                "{pump_name} {outlet} seed {seed}"
            );
            assert!(lp.run_ticks >= 4_000);
            runs += 1;
        }
    }
    println!("{pump_name}: {runs} healthy runs, no fault");
}

const SEEDS: [u64; 4] = [1, 2, 3, 4];

#[test]
fn no_false_alarm_on_the_healthy_default_blower() {
    healthy("default", &SEEDS);
}

#[test]
fn no_false_alarm_on_the_healthy_small_blower() {
    healthy("small", &SEEDS);
}

#[test]
fn no_false_alarm_on_the_healthy_sluggish_blower() {
    healthy("sluggish", &SEEDS);
}
