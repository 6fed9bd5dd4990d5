//! The 100 Hz application loop (`ridge_pump_firmware::app`) on the host, with the fakes of
//! what a board provides (`firmware-testkit`): an SFM3300 on an embedded-hal I2C bus serving
//! the readings of the synthetic plant (`common::Plant`), a PWM channel that drives that
//! plant, a UART that collects the lines, and a `Board` with a simulated clock (every
//! `poll_tick` costs [`POLL_US`], every sensor read the time the test gives it), a watchdog
//! counter and a record store.
//!
//! Checked: tick accounting (late passes, lost ticks, the `MISSED` line), the event lines of a
//! whole identification, the persistence request and its `PERSIST` line, the search in both
//! modes (ticking from the search's progress calls, and blocking with the guard), a sensor fault
//! during the search (pump stopped before the search returns), a PWM error, a sensor that never
//! starts, and that the watchdog is petted through the long search.

mod common;

use firmware_testkit::{self as testkit, FakePwm, FakeSensor, Uart, POLL_US, TICK_US};
use ridge_core::{Method, RidgeM, Search};
use ridge_pump_firmware::app::{App, Console, ANSWER_ROOM, START_TICKS};
use ridge_pump_firmware::excitation::FlowSteps;
use ridge_pump_firmware::lines::{MapLine, ParsedLine, ScanLine};
use ridge_pump_firmware::persist;
use ridge_pump_firmware::pump::Pump;
use ridge_pump_firmware::selfid::{Config, SelfIdentification, State, DEFAULT_CONFIG};
use ridge_pump_firmware::sfm3300::Sfm3300;
use ridge_pump_firmware::units::DUTY_FULL_SCALE;

use common::Plant;

/// Resolution of the fake PWM channel (`max_duty_cycle`).
const PWM_MAX: u16 = 1000;

type World = testkit::World<Plant>;
type Shared = testkit::Shared<Plant>;
type FakeBoard<const TICKING: bool> = testkit::FakeBoard<Plant, TICKING>;

/// The world of these tests: the synthetic plant behind a PWM channel of [`PWM_MAX`] counts.
fn world(plant: Plant) -> Shared {
    testkit::world(plant, PWM_MAX)
}

/// A board without a console; the ticking one reports stack figures (1234 B used, 4321 B
/// free) as a board that measures its stack.
fn board<const TICKING: bool>(w: &Shared) -> FakeBoard<TICKING> {
    FakeBoard {
        stack: TICKING.then_some((1234, 4321)),
        ..FakeBoard::new(w)
    }
}

/// The blocking board with a console.
fn console_board(w: &Shared) -> FakeBoard<false> {
    FakeBoard {
        console: Some(Console::new()),
        ..board(w)
    }
}

type TestApp = App<FakeSensor<Plant>, FakePwm<Plant>, Uart>;

fn app(w: &Shared, uart: &Uart) -> TestApp {
    app_with(w, uart, &DEFAULT_CONFIG)
}

fn app_with(w: &Shared, uart: &Uart, config: &'static Config) -> TestApp {
    let sensor = Sfm3300::new(FakeSensor(w.clone()));
    let pump = Pump::new(FakePwm(w.clone())).unwrap();
    let sid = SelfIdentification::new(config, None);
    App::new(sensor, pump, uart.clone(), sid, 400_000)
}

/// The default settings with a search that runs for many tick boundaries, so that faults,
/// commands and ticks can happen while it runs: Ridge-M to 3 000 iterates without a
/// tolerance (a pet each). With the defaults it converges in ~10 iterates on the pump's
/// records (0.6 s on the ATmega2560, most of it the bounds), on this plant within a few ticks
/// of the fake board's clock.
static SLOW_SEARCH: Config = Config {
    search: Search {
        method: Method::RidgeM(RidgeM {
            max_iter: 3_000,
            tol: 0.0,
            ..RidgeM::PAPER
        }),
        ..DEFAULT_CONFIG.search
    },
    ..Config::DEFAULT
};

/// Steps the loop until `until` holds or `max_steps` passes ran; returns the passes run.
fn run_until<const T: bool>(
    app: &mut TestApp,
    board: &mut FakeBoard<T>,
    max_steps: usize,
    until: impl Fn(&TestApp) -> bool,
) -> usize {
    for i in 0..max_steps {
        if until(app) {
            return i;
        }
        app.step(board);
    }
    panic!("condition not reached in {max_steps} passes");
}

/// Whether the next pass ends the estimation record, and therefore runs the search.
fn search_is_next(a: &TestApp) -> bool {
    let n = u32::from(Config::default().records.samples);
    a.selfid().gram().is_some_and(|g| g.len() + 1 == n)
}

fn count(lines: &[String], prefix: &str) -> usize {
    lines.iter().filter(|l| l.starts_with(prefix)).count()
}

/// The text of field `key` in a report line (the firmware's parser).
fn field(line: &str, key: &str) -> String {
    ParsedLine::parse(line)
        .get(key)
        .unwrap_or_else(|| panic!("{key} in {line}"))
        .to_owned()
}

/// A whole power-up identification, in either search mode: the expected lines in order,
/// the search's tick accounting, the record handed to the store (decodes to the model the
/// state machine runs), `PERSIST saved`, and the loop never left the watchdog unpetted for
/// more than a tick and a poll, not even during the search.
fn identifies<const TICKING: bool>() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<TICKING>(&w);
    let mut app = app(&w, &uart);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, |a| {
        a.selfid().state() == State::Run
    });
    app.step(&mut board); // the DESIGN line
    let lines = uart.lines();
    let order = [
        "SENSOR ready tries=",
        "SCAN n=",
        "MAP first=",
        "EXCITE flow-steps",
        "ID p=",
        "VALIDATE flow-steps",
        "SEARCH ticks=",
        "ACCEPT fit=",
        "PERSIST saved",
        "CTRL method=pole-placement",
        "DESIGN ticks=",
    ];
    let mut at = 0;
    for prefix in order {
        let pos = lines[at..]
            .iter()
            .position(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("{prefix} after line {at} in {lines:#?}"));
        at += pos + 1;
    }
    // The reference plant is first order with 3 samples of transport delay.
    let id = lines.iter().find(|l| l.starts_with("ID ")).unwrap();
    assert_eq!(field(id, "d"), "3", "{id}");
    assert!(field(id, "p").parse::<u8>().unwrap() >= 1);
    // Tick boundaries the search saw: the search takes many polls of simulated time.
    let search = lines.iter().find(|l| l.starts_with("SEARCH ")).unwrap();
    let ticks: u32 = field(search, "ticks").parse().unwrap();
    assert!(ticks >= 2, "{search}");
    assert_eq!(field(search, "lost"), "0", "{search}");
    // Only the ticking board reports its stack (the fake's figures), after the search and
    // after the design.
    assert_eq!(
        count(&lines, "STACK used=1234 free=4321"),
        2 * usize::from(TICKING)
    );
    // One record stored, and it is the model in use with its fit.
    assert_eq!(board.saves.len(), 1);
    let (model, map, fit) = persist::decode(&board.saves[0]).unwrap();
    assert_eq!(Some(&model), app.selfid().model());
    assert_eq!(Some(&map), app.selfid().map());
    assert_eq!(Some(fit), app.selfid().fit());
    // No late passes or lost ticks in normal operation.
    assert_eq!(count(&lines, "MISSED"), 0, "{lines:#?}");
    // The watchdog: petted every pass and through the search.
    let w = w.borrow();
    assert!(
        w.longest_unpetted <= TICK_US + POLL_US,
        "{}",
        w.longest_unpetted
    );
}

fn board_saved(uart: &Uart) -> bool {
    uart.lines().iter().any(|l| l.starts_with("PERSIST"))
}

#[test]
fn identifies_with_a_blocking_search() {
    identifies::<false>();
}

#[test]
fn identifies_with_a_ticking_search() {
    identifies::<true>();
}

/// A ticking search keeps the state machine running: the pump holds the base duty through it
/// (the PWM is written at every tick boundary the search's progress calls see).
#[test]
fn ticking_search_keeps_writing_the_pump() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<true>(&w);
    let mut app = app_with(&w, &uart, &SLOW_SEARCH);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, search_is_next);
    let (t0, writes0) = {
        let w = w.borrow();
        (w.clock, w.pwm_log.len())
    };
    app.step(&mut board); // the tick, then the whole search
    let w = w.borrow();
    let during: Vec<_> = w.pwm_log[writes0..]
        .iter()
        .filter(|(t, _)| *t > t0)
        .collect();
    let boundaries = (w.clock - t0) / TICK_US;
    assert!(
        boundaries >= 3,
        "search took {boundaries} ticks of simulated time"
    );
    assert!(
        during.len() as u64 >= boundaries,
        "{} writes, {boundaries} ticks",
        during.len()
    );
    let base = Config::default().base_duty;
    let counts = (u32::from(base) * u32::from(PWM_MAX) / u32::from(DUTY_FULL_SCALE)) as u16;
    assert!(during.iter().all(|(_, c)| *c == counts), "{during:?}");
}

/// Tick accounting: a pass whose work overruns into the next period is late; one that overruns
/// by more than a period also loses the ticks it skipped. `MISSED` reports the totals once a
/// second, only when they changed.
#[test]
fn late_passes_and_lost_ticks_are_counted_and_reported() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<false>(&w);
    let mut app = app(&w, &uart);
    app.start(&mut board);
    for _ in 0..150 {
        app.step(&mut board);
    }
    assert_eq!(count(&uart.lines(), "MISSED"), 0);
    // One read that takes 12 ms: the next boundary has passed when the loop comes back (late),
    // none was skipped. Later one of 35 ms: late, and of the three boundaries that passed
    // (+10, +20, +30 ms) the loop handles the last, so two ticks are lost.
    w.borrow_mut().next_read_us = 12_000;
    for _ in 0..50 {
        app.step(&mut board);
    }
    w.borrow_mut().next_read_us = 35_000;
    for _ in 0..300 {
        app.step(&mut board);
    }
    let missed: Vec<_> = uart
        .lines()
        .into_iter()
        .filter(|l| l.starts_with("MISSED"))
        .collect();
    assert_eq!(
        missed,
        ["MISSED late=1 lost=0", "MISSED late=2 lost=2"],
        "{:#?}",
        uart.lines()
    );
}

/// A sensor that dies while the blocking search runs: the guard reads it at the tick
/// boundaries the search's progress calls see and stops the pump after the fault limit, long
/// before the search returns; the fault is reported after the search and latched.
#[test]
fn sensor_fault_during_the_blocking_search_stops_the_pump_at_once() {
    let (stop, searched, fault) = fault_during_the_blocking_search(|w| w.sensor_dead = true);
    let limit = u64::from(Config::default().sensor_fault_limit);
    // Stopped within the fault limit's ticks (plus one for the boundary in progress) ...
    assert!(stop <= (limit + 1) * TICK_US, "stopped after {stop} µs");
    // ... while the search went on for much longer.
    assert!(searched > 3 * (limit + 1) * TICK_US, "search {searched} µs");
    assert!(fault.starts_with("FAULT sensor"), "{fault}");
}

/// Runs to the blocking search, injects `fault` into the plant at its start and returns the
/// simulated times from the injection to the pump's stop and to the search's end (µs), and the
/// `FAULT` line; checks that the fault is latched and reported once.
fn fault_during_the_blocking_search(fault: impl FnOnce(&mut World)) -> (u64, u64, String) {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<false>(&w);
    let mut app = app_with(&w, &uart, &SLOW_SEARCH);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, search_is_next);
    let t0 = {
        let mut w = w.borrow_mut();
        fault(&mut w);
        w.clock
    };
    app.step(&mut board); // the tick, then the search
    let stop = w
        .borrow()
        .pwm_log
        .iter()
        .find(|(t, c)| *t >= t0 && *c == 0)
        .map(|(t, _)| t - t0)
        .expect("the pump was stopped");
    let searched = w.borrow().clock - t0;
    assert!(searched > stop, "stopped before the search returned");
    let lines = uart.lines();
    let fault = lines
        .iter()
        .find(|l| l.starts_with("FAULT"))
        .expect("FAULT line")
        .clone();
    assert_eq!(app.selfid().state(), State::Fault);
    for _ in 0..20 {
        app.step(&mut board);
    }
    assert_eq!(w.borrow().pwm, 0);
    assert_eq!(count(&uart.lines(), "FAULT"), 1, "reported once");
    (stop, searched, fault)
}

/// A sensor that freezes at its current reading while the blocking search runs: the keepalive's
/// guard sees `frozen_ticks` identical readings and stops the pump within them (plus the
/// boundary in progress), before the search returns.
#[test]
fn frozen_sensor_during_the_blocking_search_stops_the_pump() {
    let (stop, _, fault) = fault_during_the_blocking_search(|w| w.plant.stuck = Some(w.reading));
    let limit = u64::from(Config::default().frozen_ticks);
    assert!(stop <= (limit + 1) * TICK_US, "stopped after {stop} µs");
    assert!(fault.starts_with("FAULT sensor=frozen flow="), "{fault}");
}

/// A pump that gives no flow any more (the plant's reading drops to 0 at once) while the
/// blocking search holds the 30 % base duty, below the 40 % stall duty: the keepalive's guard
/// expects the settled operating point (about 20 slm) and stops the pump after `loss_ticks`
/// ticks below a quarter of it.
#[test]
fn lost_flow_during_the_blocking_search_stops_the_pump() {
    let (stop, _, fault) = fault_during_the_blocking_search(|w| w.plant.stuck = Some(0));
    let limit = u64::from(Config::default().loss_ticks);
    assert!(stop <= (limit + 1) * TICK_US, "stopped after {stop} µs");
    assert!(stop >= limit * TICK_US, "stopped after {stop} µs");
    assert!(
        fault.starts_with("FAULT noflow duty=30.00 flow=0.000 expect="),
        "{fault}"
    );
}

/// The same fault while a ticking search runs: the state machine's own tick checks latch it
/// and the pump is stopped within the fault limit.
#[test]
fn sensor_fault_during_the_ticking_search_stops_the_pump_at_once() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<true>(&w);
    let mut app = app_with(&w, &uart, &SLOW_SEARCH);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, search_is_next);
    let t0 = {
        let mut w = w.borrow_mut();
        w.sensor_dead = true;
        w.clock
    };
    app.step(&mut board);
    let w_ = w.borrow();
    let stop = w_
        .pwm_log
        .iter()
        .find(|(t, c)| *t >= t0 && *c == 0)
        .expect("the pump was stopped");
    let limit = u64::from(Config::default().sensor_fault_limit);
    assert!(
        stop.0 - t0 <= (limit + 1) * TICK_US,
        "stopped after {} µs",
        stop.0 - t0
    );
    drop(w_);
    assert_eq!(app.selfid().state(), State::Fault);
    assert_eq!(
        count(&uart.lines(), "FAULT sensor"),
        1,
        "{:#?}",
        uart.lines()
    );
}

/// A PWM channel that refuses a duty: `PUMP error`, and the loop carries on.
#[test]
fn pwm_error_is_reported() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<false>(&w);
    let mut app = app(&w, &uart);
    app.start(&mut board);
    for _ in 0..10 {
        app.step(&mut board);
    }
    w.borrow_mut().pwm_broken = true;
    app.step(&mut board);
    assert_eq!(count(&uart.lines(), "PUMP error"), 1);
}

/// A sensor that never acknowledges: the start is retried once per tick for
/// [`START_TICKS`] ticks, then `SENSOR start failed`, and the state machine's fault checks
/// latch the sensor fault with the pump stopped.
#[test]
fn absent_sensor_fails_the_start_and_faults() {
    let w = world(Plant::reference());
    w.borrow_mut().sensor_dead = true;
    let uart = Uart::default();
    let mut board = board::<false>(&w);
    let mut app = app(&w, &uart);
    app.start(&mut board);
    assert_eq!(uart.lines(), ["SENSOR start failed"]);
    assert_eq!(w.borrow().clock / TICK_US, u64::from(START_TICKS));
    for _ in 0..10 {
        app.step(&mut board);
    }
    assert_eq!(app.selfid().state(), State::Fault);
    assert!(w.borrow().pwm_log.iter().all(|(_, c)| *c == 0));
    assert_eq!(
        count(&uart.lines(), "FAULT sensor"),
        1,
        "{:#?}",
        uart.lines()
    );
}

/// A failed record write is reported as such.
#[test]
fn failed_store_is_reported() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = board::<false>(&w);
    board.store_ok = false;
    let mut app = app(&w, &uart);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, |_| board_saved(&uart));
    assert_eq!(count(&uart.lines(), "PERSIST failed"), 1);
    assert_eq!(count(&uart.lines(), "PERSIST saved"), 0);
}

// ------------------------------------------------------------------------------- console

/// A board with a console, its app, and the app run to run mode (blocking search).
fn running() -> (Shared, Uart, FakeBoard<false>, TestApp) {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = console_board(&w);
    let mut app = app(&w, &uart);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, |a| {
        a.selfid().state() == State::Run
    });
    (w, uart, board, app)
}

/// Sends `line`, runs passes until its answer (a line starting with `OK`, `ERR`, `STATUS`,
/// `MODEL`) appeared, and returns that answer.
fn ask(board: &mut FakeBoard<false>, app: &mut TestApp, uart: &Uart, line: &str) -> String {
    let before = uart.lines().len();
    board.send(line, 0);
    for _ in 0..5 {
        app.step(board);
        let lines = uart.lines();
        if let Some(answer) = lines[before..].iter().find(|l| {
            ["OK ", "ERR ", "STATUS ", "MODEL "]
                .iter()
                .any(|p| l.starts_with(p))
        }) {
            return answer.clone();
        }
    }
    panic!("no answer to {line:?}: {:#?}", &uart.lines()[before..]);
}

/// Mean plant flow (slm) over the next `ticks` passes.
fn mean_flow(board: &mut FakeBoard<false>, app: &mut TestApp, w: &Shared, ticks: usize) -> f64 {
    let mut sum = 0.0;
    for _ in 0..ticks {
        app.step(board);
        sum += f64::from(w.borrow().reading) / 120.0;
    }
    sum / ticks as f64
}

#[test]
fn stop_turns_the_pump_off_in_the_same_pass_until_start() {
    let (w, uart, mut board, mut app) = running();
    mean_flow(&mut board, &mut app, &w, 200);
    assert!(w.borrow().pwm > 0);
    board.send("STOP\n", 0);
    app.step(&mut board);
    // The pass that received the line wrote 0 to the PWM.
    assert_eq!(w.borrow().pwm, 0);
    assert_eq!(app.selfid().state(), State::Stopped);
    assert!(uart.lines().iter().any(|l| l == "OK stop"));
    for _ in 0..300 {
        app.step(&mut board);
        assert_eq!(w.borrow().pwm, 0, "latched until START");
    }
    assert_eq!(ask(&mut board, &mut app, &uart, "START\n"), "OK start");
    // As after a reset with the model in RAM: settle, LOADED, design, run.
    run_until(&mut app, &mut board, 1_000, |a| {
        a.selfid().state() == State::Run
    });
    assert!(uart.lines().iter().any(|l| l.starts_with("LOADED ")));
    mean_flow(&mut board, &mut app, &w, 200);
    assert!(w.borrow().pwm > 0);
    // START while running changes nothing.
    assert_eq!(ask(&mut board, &mut app, &uart, "START\n"), "ERR state");
}

/// A `STOP` that arrives while the loop waits for the next tick stops the pump there, one poll
/// after its last byte and before the boundary; the answer comes with the next pass.
#[test]
fn stop_received_while_waiting_stops_the_pump_before_the_next_tick() {
    let (w, uart, mut board, mut app) = running();
    mean_flow(&mut board, &mut app, &w, 200);
    assert!(w.borrow().pwm > 0);
    // The last byte arrives 6 ms into the interval, after this pass's work.
    let (now, boundary) = (w.borrow().clock, w.borrow().last_boundary);
    let arrival = boundary + 6_000;
    assert!(now < arrival, "the pass ran {} µs", now - boundary);
    board.send("STOP\n", arrival - now);
    w.borrow_mut().pwm_log.clear();
    app.step(&mut board);
    let log = w.borrow().pwm_log.clone();
    let (t, counts) = log.first().copied().expect("a PWM write");
    assert_eq!(counts, 0, "the first write is the stop: {log:?}");
    assert!(
        t >= arrival && t <= arrival + POLL_US && t < boundary + TICK_US,
        "PWM 0 at {} µs, STOP at {} µs, boundary at {} µs",
        t - boundary,
        arrival - boundary,
        TICK_US
    );
    assert_eq!(app.selfid().state(), State::Stopped);
    assert!(uart.lines().iter().any(|l| l == "OK stop"));
}

/// A command is executed only when the transmit queue has [`ANSWER_ROOM`] bytes free (so its
/// answer never makes the loop wait for the line), and `MODEL`'s `RST` lines (one per
/// polynomial) come in the passes after it, one per pass, under the same condition; the line
/// waits meanwhile.
#[test]
fn answers_wait_for_room_in_the_transmit_queue() {
    let (_w, uart, mut board, mut app) = running();
    let from = uart.lines().len();
    let answers = |uart: &Uart| -> Vec<String> {
        uart.lines()[from..]
            .iter()
            .filter(|l| ["MODEL ", "MAP ", "RST "].iter().any(|k| l.starts_with(k)))
            .cloned()
            .collect()
    };
    board.room = ANSWER_ROOM - 1;
    board.send("MODEL\n", 0);
    for _ in 0..50 {
        app.step(&mut board);
    }
    assert!(answers(&uart).is_empty(), "{:?}", answers(&uart));
    board.room = ANSWER_ROOM;
    app.step(&mut board);
    let got = answers(&uart);
    assert!(got.len() == 1 && got[0].starts_with("MODEL p="), "{got:?}");
    board.room = ANSWER_ROOM - 1;
    for _ in 0..50 {
        app.step(&mut board);
    }
    assert_eq!(answers(&uart).len(), 1);
    // The map, then one polynomial per pass, each once there is room.
    for (n, prefix) in [
        (2, "MAP first="),
        (3, "RST r=1.000000,"),
        (4, "RST s="),
        (5, "RST t="),
    ] {
        board.room = ANSWER_ROOM;
        app.step(&mut board);
        let got = answers(&uart);
        assert!(got.len() == n && got[n - 1].starts_with(prefix), "{got:?}");
        board.room = ANSWER_ROOM - 1;
        app.step(&mut board);
        assert_eq!(answers(&uart).len(), n);
    }
    // Nothing else was waiting.
    board.room = usize::MAX;
    assert_eq!(
        ask(&mut board, &mut app, &uart, "STATUS\n")
            .split(' ')
            .next(),
        Some("STATUS")
    );
}

#[test]
fn stop_during_the_blocking_search_stops_the_pump_at_the_next_tick_boundary() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = console_board(&w);
    let mut app = app_with(&w, &uart, &SLOW_SEARCH);
    app.start(&mut board);
    run_until(&mut app, &mut board, 8_000, search_is_next);
    // Arrives 25 ms into the search (the search blocks the loop far longer in simulated time).
    board.send("STOP\n", 25_000);
    w.borrow_mut().pwm_log.clear();
    app.step(&mut board);
    let t_stop = w
        .borrow()
        .pwm_log
        .iter()
        .find(|&&(_, d)| d == 0)
        .map(|&(t, _)| t);
    let t_sent = w.borrow().pwm_log.first().map(|&(t, _)| t).unwrap();
    let t_stop = t_stop.expect("the keepalive stopped the pump");
    assert!(
        t_stop <= t_sent + 25_000 + TICK_US + POLL_US,
        "stopped {} µs after the search began",
        t_stop - t_sent
    );
    app.step(&mut board);
    assert_eq!(app.selfid().state(), State::Stopped);
    assert!(uart.lines().iter().any(|l| l == "OK stop"));
    for _ in 0..100 {
        app.step(&mut board);
        assert_eq!(w.borrow().pwm, 0);
    }
}

#[test]
fn set_flow_is_tracked_by_the_designed_controller() {
    let (w, uart, mut board, mut app) = running();
    for target in [45.0, 30.0] {
        let line = format!("SET flow={target}\n");
        assert_eq!(ask(&mut board, &mut app, &uart, &line), "OK set");
        app.step(&mut board);
        assert_eq!(app.selfid().setpoint(), Some(target as f32));
        mean_flow(&mut board, &mut app, &w, 400);
        let flow = mean_flow(&mut board, &mut app, &w, 100);
        assert!(
            (flow - target).abs() < 0.01 * target,
            "flow {flow:.3} slm for a setpoint of {target} slm"
        );
    }
}

#[test]
fn profile_runs_the_breath_it_names() {
    use ridge_pump_firmware::setpoint::{Breath, Shape};
    let (_w, uart, mut board, mut app) = running();
    let line = "profile RAMP peak=50 bias=12.5 rate=15 ie=1.5 rise=0.25\r\n";
    assert_eq!(ask(&mut board, &mut app, &uart, line), "OK profile");
    let b = Breath {
        shape: Shape::Ramp,
        rate: 15.0,
        ie: 1.5,
        peak: 50.0,
        bias: 12.5,
        rise: 0.25,
    };
    // Two breaths (400 ticks each) of setpoints, against the definition sampled every 10 ms
    // from some phase.
    let mut got = Vec::new();
    for _ in 0..800 {
        app.step(&mut board);
        got.push(app.selfid().setpoint().unwrap());
    }
    let best = (0..400)
        .map(|k0| {
            got.iter()
                .enumerate()
                .map(|(k, &r)| (r - b.at(((k + k0) % 400) as f32 * 0.01)).abs())
                .fold(0.0f32, f32::max)
        })
        .fold(f32::INFINITY, f32::min);
    assert!(best < 1e-3, "largest difference from the breath {best}");
}

/// The limits themselves are accepted, each the breath it names: half the inspiration (1 s at
/// 20 /min, 1:2; 5 s at 4 /min, 1:0.5), 60 /min, I:E 1:10, 0 and 250 slm (the flow limit).
#[test]
fn profile_limits_are_accepted() {
    use ridge_pump_firmware::setpoint::{Breath, BreathWave, Program, Shape};
    let (_w, uart, mut board, mut app) = running();
    for (line, shape, rate, ie, peak, bias, rise) in [
        (
            "PROFILE square rise=0.5\n",
            Shape::Square,
            20.0,
            2.0,
            60.0,
            10.0,
            0.5,
        ),
        (
            "PROFILE ramp rate=4 ie=0.5 rise=5\n",
            Shape::Ramp,
            4.0,
            0.5,
            60.0,
            10.0,
            5.0,
        ),
        (
            "PROFILE square rate=60 ie=10 rise=0\n",
            Shape::Square,
            60.0,
            10.0,
            60.0,
            10.0,
            0.0,
        ),
        (
            "PROFILE ramp peak=250 bias=0\n",
            Shape::Ramp,
            20.0,
            2.0,
            250.0,
            0.0,
            0.3,
        ),
    ] {
        assert_eq!(
            ask(&mut board, &mut app, &uart, line),
            "OK profile",
            "{line:?}"
        );
        let b = Breath {
            shape,
            rate,
            ie,
            peak,
            bias,
            rise,
        };
        assert_eq!(
            app.selfid().program(),
            Program::Breath(BreathWave::new(&b)),
            "{line:?}"
        );
    }
}

#[test]
fn bad_commands_answer_err_and_change_nothing() {
    let (_w, uart, mut board, mut app) = running();
    let program = app.selfid().program();
    for (line, answer) in [
        ("SET flow=999\n", "ERR range flow"),
        ("SET flow=-1\n", "ERR range flow"),
        ("SET flow=4x\n", "ERR number"),
        ("SET flow=1.2345\n", "ERR number"),
        ("SET pressure=4\n", "ERR field"),
        ("SET\n", "ERR missing"),
        ("SET flow=40 now\n", "ERR field"),
        ("FLY\n", "ERR unknown"),
        ("PROFILE square rise=5\n", "ERR range rise"),
        // Half the inspiration of 20 /min at 1:2 (T_i = 1 s) is 0.5 s; 4 /min at 1:0.5 gives 5 s.
        ("PROFILE square rise=0.501\n", "ERR range rise"),
        ("PROFILE ramp rate=4 ie=0.5 rise=5.001\n", "ERR range rise"),
        ("PROFILE square rise=-0.001\n", "ERR range rise"),
        ("PROFILE square rate=60.001\n", "ERR range rate"),
        ("PROFILE square ie=0\n", "ERR range ie"),
        ("PROFILE square ie=10.001\n", "ERR range ie"),
        ("PROFILE square peak=250.001\n", "ERR range flow"),
        ("PROFILE square bias=-0.001\n", "ERR range flow"),
        ("PROFILE square rate=0\n", "ERR range rate"),
        ("PROFILE sine\n", "ERR field"),
        ("PROFILE square peak\n", "ERR field"),
        ("LOG maybe\n", "ERR field"),
    ] {
        assert_eq!(ask(&mut board, &mut app, &uart, line), answer, "{line:?}");
        assert_eq!(
            app.selfid().program(),
            program,
            "{line:?} changed the program"
        );
        assert_eq!(app.selfid().state(), State::Run);
    }
    let long = format!("SET flow=40{}\n", " ".repeat(100));
    assert_eq!(ask(&mut board, &mut app, &uart, &long), "ERR too-long");
    // Bytes lost after `SET fl`: the rest of the line comes 2 ms later.
    board.rx_lost = true;
    board.send("SET fl", 0);
    board.send("ow=40\n", 2_000);
    assert_eq!(ask(&mut board, &mut app, &uart, ""), "ERR overrun");
    assert_eq!(app.selfid().program(), program);
    // The next line is fine again.
    assert_eq!(ask(&mut board, &mut app, &uart, "SET flow=40\n"), "OK set");
}

#[test]
fn status_model_and_forget_answer() {
    let (w, uart, mut board, mut app) = running();
    let status = ask(&mut board, &mut app, &uart, "STATUS\n");
    assert!(status.starts_with("STATUS state=run "), "{status}");
    // The last reading, rounded to milli-slm.
    let counts = app.selfid().reading();
    assert_eq!(counts, w.borrow().reading);
    let want = format!("{:.3}", f64::from(counts) / 120.0);
    assert_eq!(field(&status, "flow"), want);
    assert_eq!(field(&status, "fault"), "none");
    let model = ask(&mut board, &mut app, &uart, "MODEL\n");
    let id = uart
        .lines()
        .into_iter()
        .find(|l| l.starts_with("ID "))
        .unwrap();
    for key in ["p", "q", "d", "theta", "phi", "c"] {
        assert_eq!(field(&model, key), field(&id, key), "{key}");
    }
    for _ in 0..4 {
        app.step(&mut board);
    }
    // The map line after MODEL is the one identification printed.
    let maps: Vec<String> = uart
        .lines()
        .into_iter()
        .filter(|l| l.starts_with("MAP "))
        .collect();
    assert_eq!(maps.len(), 2, "{maps:?}");
    assert_eq!(maps[0], maps[1]);
    for prefix in ["RST r=1.000000,", "RST s=", "RST t="] {
        assert!(
            uart.lines().iter().any(|l| l.starts_with(prefix)),
            "{prefix}"
        );
    }
    let saves = board.saves.len();
    assert_eq!(ask(&mut board, &mut app, &uart, "FORGET\n"), "OK forget");
    let erased = board.saves.get(saves).expect("a write");
    assert!(erased.iter().all(|&b| b == 0xFF));
    assert!(persist::decode(erased).is_err());
}

#[test]
fn log_rows_are_the_samples_of_the_record() {
    let w = world(Plant::reference());
    let uart = Uart::default();
    let mut board = console_board(&w);
    let mut app = app(&w, &uart);
    app.start(&mut board);
    assert_eq!(ask(&mut board, &mut app, &uart, "LOG on\n"), "OK log");
    run_until(&mut app, &mut board, 8_000, |a| {
        a.selfid().state() == State::Run
    });
    mean_flow(&mut board, &mut app, &w, 300);
    let lines = uart.lines();
    let header = lines.iter().position(|l| l == "t,u,y,r,phase").unwrap();
    let rows: Vec<Vec<&str>> = lines[header + 1..]
        .iter()
        .filter(|l| l.starts_with(|c: char| c.is_ascii_digit()))
        .map(|l| l.split(',').collect())
        .collect();
    assert!(rows.iter().all(|r| r.len() == 5), "five columns");
    // Time: 10 ms a row, gaps only over the blocking search and design.
    let t: Vec<i64> = rows
        .iter()
        .map(|r| (r[0].parse::<f64>().unwrap() * 100.0).round() as i64)
        .collect();
    let gaps = t.windows(2).filter(|p| p[1] - p[0] != 1).count();
    assert!(t.windows(2).all(|p| p[1] > p[0]));
    assert!(gaps <= 2, "{gaps} gaps");
    // The excitation rows: as many as the record has samples, each duty the one the pump
    // held during the interval before the reading, each flow the plant's reading.
    let excite: Vec<&Vec<&str>> = rows.iter().filter(|r| r[4] == "excite").collect();
    let records = Config::default().records;
    assert_eq!(excite.len(), usize::from(records.samples));
    // Every duty is the record's: its generator rebuilt from the MAP and SCAN lines.
    let line = |k: &str| lines.iter().find(|l| l.starts_with(k)).unwrap();
    let map = MapLine::parse(line("MAP ")).unwrap().map;
    let lag = ScanLine::parse(line("SCAN ")).unwrap().lag;
    let mut gen = FlowSteps::new(&map, &records.shape(lag, records.samples, records.seed)).unwrap();
    for (i, r) in excite.iter().enumerate() {
        let duty = (r[1].parse::<f64>().unwrap() * 1e4).round() as u16;
        assert_eq!(Some(duty), gen.next_step().map(|s| s.0), "duty {i}");
    }
    for r in &excite {
        let y: f64 = r[2].parse().unwrap();
        let counts = (y * 120.0).round();
        assert!(
            (y * 120.0 - counts).abs() < 1e-3,
            "y = counts / 120 to 5 decimals: {y}"
        );
    }
    // Run mode rows carry the setpoint.
    let run: Vec<&Vec<&str>> = rows.iter().filter(|r| r[4] == "run").collect();
    assert!(run.len() >= 300);
    assert!(run.iter().all(|r| r[3].parse::<f32>().is_ok()));
    assert!(excite.iter().all(|r| r[3].is_empty()));
    // A full transmit queue drops rows and says so.
    board.room = 10;
    let n = uart.lines().len();
    mean_flow(&mut board, &mut app, &w, 150);
    let later = &uart.lines()[n..];
    assert!(later
        .iter()
        .all(|l| !l.starts_with(|c: char| c.is_ascii_digit())));
    assert!(later.iter().any(|l| l.starts_with("LOG dropped=")));
}
