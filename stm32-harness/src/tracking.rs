//! Run mode seen from the bench, for `harness_kit::run` (which rebuilds it tick by tick and
//! checks it against the `TRACK` lines): the loop's passes as ticks ([`crate::ticks`]; in run
//! mode each pass is one 10 ms tick), the lines with when their first byte left USART1, the
//! frames the SFM3300 served and the duty on PA6, in picoseconds.

use harness_kit::run::{RunInput, RunTrace};
use pump_sim::Valve;
use ridge_pump_firmware::setpoint::VolumeBreath;

use crate::bench::Bench;
use crate::periph::PS_PER_S;

/// Run mode rebuilt from `bench` (`harness_kit::run::RunTrace::rebuild`); an error says what
/// is missing (no `CTRL` line, no `TRACK` lines, no ticks).
pub fn run_trace(bench: &Bench) -> Result<RunTrace, String> {
    run_trace_vent(bench, None)
}

/// [`run_trace`] of a run that was sent a `VENT` command with the breath settings `vent`: the
/// volume program, its `BREATH` lines and (when printed) the `REID` lines replayed
/// ([`RunTrace::replayed`]).
pub fn run_trace_vent(bench: &Bench, vent: Option<VolumeBreath>) -> Result<RunTrace, String> {
    let duty_at = |t: u64| bench.duty_at(t).map_or(0.0, |d| d.fraction);
    let flow_at = |t: u64| {
        let log = &bench.plant_log;
        let i = log.partition_point(|s| s.at < t);
        log.get(i).or(log.last()).map_or(0.0, |s| s.flow)
    };
    let input = RunInput {
        lines: bench
            .lines
            .iter()
            .map(|l| (l.start, l.text.as_str()))
            .collect(),
        ticks: bench
            .machine
            .core()
            .ticks
            .ticks
            .iter()
            .map(|k| k.start)
            .collect(),
        per_s: PS_PER_S as f64,
        frames: bench.sensor.borrow().served_with_flow(),
        duty_at: &duty_at,
        flow_at: &flow_at,
        now: bench.machine.now(),
        valve: bench
            .valve_log
            .iter()
            .map(|&(t, v)| (t, v == Valve::Closed))
            .collect(),
        vent,
    };
    RunTrace::rebuild(&input)
}
