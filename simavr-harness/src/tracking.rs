//! Run mode seen from the bench, for `harness_kit::run` (which rebuilds it tick by tick and
//! checks it against the `TRACK` lines, see there): the bench's ticks (tick interrupt entries),
//! the lines with the cycle their first byte left the UART, the frames the SFM3300 served and
//! the duty on the PWM pin, in core cycles; and the design's cycles, which only this bench can
//! tell (the ticks that found the main loop busy).

use harness_kit::run::RunInput;
pub use harness_kit::run::{program, RunTrace, TraceRow};
use pump_sim::Valve;
use ridge_pump_firmware::setpoint::VolumeBreath;

use crate::bench::Bench;

/// Run mode rebuilt from `bench` (`harness_kit::run::RunTrace::rebuild`); an error says what
/// is missing (no `CTRL` line, no `TRACK` lines, no ticks).
pub fn run_trace(bench: &Bench) -> Result<RunTrace, String> {
    rebuild(bench, None)
}

/// As [`run_trace`] for a run that was sent `VENT` with the settings `breath`: the volume
/// program from the tick that first closed the exhalation valve on, replayed.
pub fn run_trace_ventilated(bench: &Bench, breath: VolumeBreath) -> Result<RunTrace, String> {
    rebuild(bench, Some(breath))
}

fn rebuild(bench: &Bench, vent: Option<VolumeBreath>) -> Result<RunTrace, String> {
    let duty_at = |c: u64| bench.duty_at(c).map_or(0.0, |d| d.fraction);
    let flow_at = |c: u64| {
        // No frame (sensor fault): the plant sample nearest the tick.
        let i = bench.plant_log.partition_point(|s| s.cycle < c);
        bench
            .plant_log
            .get(i)
            .or(bench.plant_log.last())
            .map_or(0.0, |s| s.flow)
    };
    let input = RunInput {
        lines: bench
            .lines
            .iter()
            .zip(&bench.line_starts)
            .map(|(l, &start)| (start, l.text.as_str()))
            .collect(),
        ticks: bench.ticks().iter().map(|t| t.start).collect(),
        per_s: f64::from(bench.frequency()),
        frames: bench.sensor.borrow().served_with_flow(),
        duty_at: &duty_at,
        flow_at: &flow_at,
        now: bench.machine.cycle(),
        valve: bench
            .valve_log
            .iter()
            .map(|&(c, v)| (c, v == Valve::Closed))
            .collect(),
        vent,
    };
    RunTrace::rebuild(&input)
}

/// Cycles the controller design took, at most: from the start of the tick in which the main
/// loop last left its idle wait before the `CTRL` line (the design runs in the main loop after
/// that tick's work) to the line's first byte. `None` without a `CTRL` line.
pub fn design_cycles(bench: &Bench) -> Option<u64> {
    let ctrl_idx = bench
        .lines
        .iter()
        .position(|l| l.text.starts_with("CTRL"))?;
    let ticks = bench.ticks();
    let ctrl_start = bench.line_starts[ctrl_idx];
    let j = ticks
        .partition_point(|t| t.start <= ctrl_start)
        .checked_sub(1)?;
    // The ticks the ISR found the main loop busy, back from the CTRL line; the design began in
    // the earliest of them.
    let mut k = j;
    while k > 0 && ticks[k].interrupted_busy {
        k -= 1;
    }
    ticks.get(k + 1).map(|t| ctrl_start.saturating_sub(t.start))
}
