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
/// takes 0.6 s on the default blower; 3 s here, for faults injected in it to be found in it) and
/// while the design runs (tens of milliseconds).
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

#[derive(Clone)]
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

    /// The duties a healthy twin of this loop (the same plant, noise and state) applies during
    /// its next `n` ticks: what the records would have driven after an injection now.
    fn ahead(&self, n: usize) -> Vec<u16> {
        let mut twin = self.clone();
        (twin.dead, twin.frozen, twin.in_watch) = (false, None, None);
        (0..n)
            .map(|_| {
                let applied = twin.duty;
                twin.tick();
                applied
            })
            .collect()
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
    /// 1 s into the first settle phase (the pump at the base duty).
    Settle,
    /// 2 s into the scan (past the top of its ramps).
    Scan,
    /// 3 s into the estimation record.
    Excite,
    /// At the first tick boundary of the blocking search.
    Search,
    /// 1 s into the validation record.
    Validate,
    /// At the first tick boundary of the blocking controller design.
    Design,
    /// 5 s into run mode (the demo program).
    Run,
}

const EVERY_STATE: [Where; 7] = [
    Where::Settle,
    Where::Scan,
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
        Where::Settle => into(lp, State::Settle, 100),
        Where::Scan => into(lp, State::Scan, 200),
        Where::Excite => into(lp, State::Excite, 300),
        Where::Validate => into(lp, State::Validate, 100),
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
    coast_ticks(p, p.steady_state_flow(0.30) / 4.0 * 0.8)
}

/// Ticks a blower with `p` needs after its PWM line died for its flow to fall from the
/// largest it gives (at 95 % duty) below `to` slm.
fn coast_ticks(p: &PumpParams, to: f64) -> usize {
    let from = p.steady_state_flow(0.95);
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

/// Where the no-flow check expects a flow after an injection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expects {
    /// Nowhere before the stall check fires: the operating point is not known yet, or (a line
    /// that died during the first settle phase) measured near zero.
    Nothing,
    /// At or above the base duty (the settled operating point's law: the scan, the records,
    /// the blocking jobs at the base duty).
    AboveBase,
    /// At every duty (run mode: the model's steady state).
    Always,
}

/// The bound for a dead PWM line, ticks after the injection, on a blower `pump` whose healthy
/// twin would have applied the duties `ahead` from the injection on (past them the base duty):
/// the stall check (after the flow coasted below the stall flow, 50 consecutive ticks at the
/// stall duty or more, one more for the applied duty's lag), or the no-flow check (the
/// coast-down below a quarter of the expected flow, then `loss_ticks` checked ticks), whichever
/// comes first.
fn dead_bound(pump: &PumpParams, ahead: &[u16], expects: Expects) -> usize {
    let cfg = Config::default();
    let duty = |k: usize| ahead.get(k).copied().unwrap_or(cfg.base_duty);
    let stall_flow = f64::from(cfg.stall_flow) / 120.0;
    let mut stall = usize::MAX;
    let mut run = 0;
    for k in coast_ticks(pump, stall_flow)..ahead.len() {
        run = if duty(k) >= cfg.stall_duty {
            run + 1
        } else {
            0
        };
        if run >= usize::from(cfg.stall_ticks) {
            stall = k + 2;
            break;
        }
    }
    let loss = match expects {
        Expects::Nothing => usize::MAX,
        _ => {
            let mut checked = 0;
            let mut k = coast_down_ticks(pump);
            while checked < usize::from(cfg.loss_ticks) {
                if expects == Expects::Always || duty(k) >= cfg.base_duty {
                    checked += 1;
                }
                k += 1;
            }
            k + 1
        }
    };
    stall.min(loss)
}

#[test]
fn a_dead_pwm_line_is_detected_in_every_state_within_the_bound() {
    let cfg = Config::default();
    let mut report = Vec::new();
    for (name, pump) in pumps() {
        for at in EVERY_STATE {
            let mut lp = Loop::new(pump.clone(), None, 5);
            inject_at(&mut lp, at, Inject::DeadPwm);
            // The first settle phase expects nothing yet (its operating point is then near
            // zero): the stall check in the scan's ramp up that follows. The blocking jobs
            // hold the base duty (every tick checked), run mode expects at every duty.
            let bound = match at {
                Where::Settle => dead_bound(&pump, &lp.ahead(3_000), Expects::Nothing),
                Where::Search | Where::Design => dead_bound(&pump, &[], Expects::AboveBase),
                Where::Run => dead_bound(&pump, &[], Expects::Always),
                _ => dead_bound(&pump, &lp.ahead(3_000), Expects::AboveBase),
            };
            let (ticks, r) = lp.detection(bound.saturating_add(50));
            assert!(
                ticks <= bound,
                "{name} {at:?}: {ticks} > {bound} ticks, {r:?}"
            );
            // The stall check (40 % or more) or the no-flow check, whichever the flow's
            // coast-down lets fire first: below the stall duty only the no-flow check can.
            match r.reason {
                FaultReason::NoFlow { .. } => {}
                FaultReason::Stall { duty, .. } => assert!(duty >= cfg.stall_duty),
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
        let bound = dead_bound(&pump, &[], Expects::Always);
        let (ticks, r) = lp.detection(bound.saturating_add(50));
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
/// nothing), and that operating point is near zero; the scan's ramp up to 95 % trips the stall
/// check within a second of the settle phase, instead of three rejected attempts.
#[test]
fn a_dead_pwm_line_from_power_up_is_a_stall_in_the_first_scan() {
    for (name, pump) in pumps() {
        let mut lp = Loop::new(pump.clone(), None, 9);
        // One wait tick, the settle phase, then the scan's ramp up to its first stall.
        let bound = dead_bound(&pump, &lp.ahead(1_000), Expects::Nothing);
        lp.inject(Inject::DeadPwm);
        let (ticks, r) = lp.detection(bound.saturating_add(50));
        assert!(ticks <= bound, "{name}: {ticks} > {bound}");
        assert!(
            matches!(r.reason, FaultReason::Stall { .. }),
            "{name}: {r:?}"
        );
        assert_eq!(r.duty, 0);
        println!("{name}: dead from power-up, stall after {ticks} ticks (bound {bound})");
    }
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
