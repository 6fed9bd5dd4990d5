//! Run mode seen from the bench: the firmware's flow controller tracking its setpoint program,
//! rebuilt tick by tick from what the bench observed, and scored with `pump_sim`'s metrics (as
//! `simavr-harness` does for the ATmega2560).
//!
//! The bench sees the duty on the pump's pin, the true flow and the words the simulated
//! SFM3300 served; the setpoint is the firmware's program (`ridge_pump_firmware::setpoint::
//! value`, the same code) from the first run tick on. Two facts from the firmware's lines pin
//! it down:
//! - **when run mode started**: each `TRACK … tick=n` line is printed in the loop pass that
//!   completed `n` run ticks; the pass ([`crate::ticks`]) in which the line's first byte left
//!   USART1 is that tick, so run tick 0 is `n − 1` passes earlier (every `TRACK` line must
//!   agree; in run mode each pass is one 10 ms tick);
//! - **the start flow** the program holds first: the first `TRACK` window lies within the
//!   demo's hold, so its mean setpoint `sp=` is the start flow (a whole number of counts).
//!
//! Each `TRACK` line's `sp=` and `flow=` are recomputed from the rebuilt trace over the same
//! ticks: they must match to the printed precision ([`RunTrace::track_mismatch`]), which
//! checks the alignment, the program and the readings at once.
//!
//! Conventions of the rebuilt [`Trace`] (as `pump_sim::baseline` scores it): interval `k` runs
//! from run tick `k` to run tick `k + 1`; `setpoint[k]` is the program's value for it,
//! `duty[k]` the duty on the pin during it, `flow[k]` / `measured[k]` the true flow and the
//! reading the firmware takes at tick `k + 1` (the end of the interval).

use pump_sim::baseline::experiment::{score, Scores, Trace};
use pump_sim::sfm3300::raw_to_flow;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::value;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_SCALE, SLM_PER_COUNT};

use crate::bench::Bench;
use crate::periph::Time;

/// Run mode rebuilt from a bench (see the module docs).
#[derive(Clone, Debug)]
pub struct RunTrace {
    /// Index of run tick 0 among the machine's ticks.
    pub first_tick: usize,
    /// When run tick 0 started, ps.
    pub first_at: Time,
    /// The start flow the program holds first, slm.
    pub start: f64,
    /// Setpoint preview from the `CTRL` line, ticks.
    pub preview: u32,
    /// The run-mode trace (one entry per complete interval).
    pub trace: Trace,
    /// `TRACK` lines checked against the rebuilt trace.
    pub track_lines: usize,
    /// Largest difference between a `TRACK` line's `sp=` / `flow=` and the same means from
    /// the rebuilt trace, slm (0.0005 is the printing's rounding).
    pub track_mismatch: f64,
    /// `TRACK` lines whose `tick=` disagreed with the first one's alignment.
    pub misaligned: usize,
}

impl RunTrace {
    /// Rebuilds run mode from `bench`; an error says what is missing (no `CTRL` line, no
    /// `TRACK` lines, no ticks).
    pub fn from_bench(bench: &Bench) -> Result<Self, String> {
        let ctrl = bench
            .lines
            .iter()
            .find(|l| l.keyword() == "CTRL")
            .ok_or("no CTRL line: the controller was not designed")?;
        let preview = ctrl
            .parsed()
            .int("preview")
            .and_then(|p| u32::try_from(p).ok())
            .ok_or("CTRL line without preview=")?;
        let ticks = &bench.machine.core().ticks.ticks;
        if ticks.len() < 2 {
            return Err("no ticks".into());
        }
        let tick_of = |t: Time| ticks.partition_point(|k| k.start <= t).checked_sub(1);
        // (tick of emission, tick=, sp, flow) of every TRACK line.
        let mut tracks = Vec::new();
        for l in bench.lines.iter().filter(|l| l.keyword() == "TRACK") {
            let p = l.parsed();
            let (Some(n), Some(sp), Some(flow)) = (p.int("tick"), p.num("sp"), p.num("flow"))
            else {
                return Err(format!("unreadable TRACK line: {}", l.text));
            };
            let j = tick_of(l.start).ok_or("TRACK line before the first tick")?;
            tracks.push((j, n, sp, flow));
        }
        let &(j1, n1, sp1, _) = tracks.first().ok_or("no TRACK line")?;
        let first_tick = usize::try_from(j1 as i64 - (n1 - 1))
            .map_err(|_| "TRACK tick= before the session started")?;
        let misaligned = tracks
            .iter()
            .filter(|&&(j, n, _, _)| j as i64 - (n - 1) != first_tick as i64)
            .count();
        let counts = (sp1 * f64::from(FLOW_SCALE)).round();
        let start = f64::from(counts as f32 * SLM_PER_COUNT);
        let program = DEFAULT_CONFIG.control.program;
        let sp_at = |k: usize| f64::from(value(program, start as f32, k as u32));

        // The reading of each tick: the first frame served within it.
        let frames = bench.sensor.borrow().served();
        let frame_of = |j: usize| -> Option<(u16, f64)> {
            let from = ticks.get(j)?.start;
            let to = ticks.get(j + 1).map_or(Time::MAX, |t| t.start);
            let i = frames.partition_point(|f| f.0 < from);
            frames
                .get(i)
                .filter(|f| f.0 < to)
                .map(|&(_, raw, flow)| (raw, flow))
        };
        let duty_of = |j: usize| -> f64 {
            let end = ticks.get(j + 1).map_or(bench.machine.now(), |t| t.start);
            bench
                .duty_at(end.saturating_sub(1))
                .map_or(0.0, |d| d.fraction)
        };

        let mut trace = Trace::default();
        for j in first_tick..ticks.len().saturating_sub(1) {
            let Some((raw, flow)) = frame_of(j + 1) else {
                continue;
            };
            trace.setpoint.push(sp_at(j - first_tick));
            trace.flow.push(flow);
            trace.measured.push(raw_to_flow(raw));
            trace.duty.push(
                (duty_of(j) * f64::from(DUTY_FULL_SCALE))
                    .round()
                    .clamp(0.0, f64::from(DUTY_FULL_SCALE)) as u16,
            );
        }

        // Every TRACK window: pairs (setpoint of interval i − 1, reading at run tick i) for i
        // in the window, the first pair with the start flow.
        let mut mismatch = 0.0f64;
        let mut prev = 0i64;
        for &(_, n, sp, flow) in &tracks {
            let (mut s_sp, mut s_y, mut m) = (0.0, 0.0, 0usize);
            for i in prev.max(0)..n {
                let i = i as usize;
                let Some((raw, _)) = frame_of(first_tick + i) else {
                    continue;
                };
                s_sp += if i == 0 { start } else { sp_at(i - 1) };
                s_y += raw_to_flow(raw);
                m += 1;
            }
            if m > 0 {
                let m = m as f64;
                mismatch = mismatch
                    .max((s_sp / m - sp).abs())
                    .max((s_y / m - flow).abs());
            }
            prev = n;
        }
        Ok(RunTrace {
            first_tick,
            first_at: ticks[first_tick.min(ticks.len() - 1)].start,
            start,
            preview,
            trace,
            track_lines: tracks.len(),
            track_mismatch: mismatch,
            misaligned,
        })
    }

    /// The run's scores (steps, breaths, duty variation) from the true flow, as
    /// `pump_sim::baseline` scores its host runs; `None` when run mode was shorter than the
    /// demo program's scored part (`pump_sim::baseline::experiment::run_ticks`).
    pub fn scores(&self) -> Option<Scores> {
        score(&self.trace, false, self.preview)
    }
}
