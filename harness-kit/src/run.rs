//! Run mode seen from a bench: the firmware's flow controller tracking its setpoint program,
//! rebuilt tick by tick from what the bench observed, and scored with `pump_sim`'s metrics.
//!
//! The bench sees the duty on the pump's pin, the true flow and the words the simulated
//! SFM3300 served; the setpoint is the firmware's program (`ridge_pump_firmware::setpoint::
//! value`, the same code) from the first run tick on. Two facts from the firmware's lines pin
//! it down:
//! - **when run mode started**: each `TRACK … tick=n` line is printed in the tick that
//!   completed `n` run ticks; the bench tick in which the line's first byte left the UART is
//!   that tick, so run tick 0 is `n − 1` bench ticks earlier (every `TRACK` line must agree);
//! - **the start flow** the program holds first: the first `TRACK` window lies within the
//!   demo's hold, so its mean setpoint `sp=` is the start flow (a whole number of sensor
//!   counts).
//!
//! Each `TRACK` line's `sp=` and `flow=` are then recomputed from the rebuilt trace over the
//! same ticks: they must match to the printed precision ([`RunTrace::track_mismatch`]), which
//! checks the alignment, the program and the readings at once.
//!
//! After a `VENT` command ([`RunInput::vent`]) the program is the volume-controlled breath
//! from the tick that first closed the exhalation valve on: its setpoints are replayed from the
//! firmware's own code (`setpoint::Setpoint` and `ventilation::Ventilation`, fed the readings the
//! firmware was served, so that the per-breath volume trim moves the amplitude exactly as it did
//! on the device), and the `TRACK` lines check them as they check the demo's.
//!
//! Every row also carries the breath and its phase from the valve's pin ([`TraceRow::breath`],
//! [`TraceRow::phase`]): the simulator's truth, not the firmware's program.
//!
//! Conventions of the rebuilt [`Trace`] (as `pump_sim::baseline` scores it): interval `k` runs
//! from run tick `k` to run tick `k + 1`; `setpoint[k]` is the program's value for it, `duty[k]`
//! the duty on the pin during it, `flow[k]` / `measured[k]` the true flow and the reading the
//! firmware takes at tick `k + 1` (the end of the interval).

use std::io::Write;
use std::path::Path;

use pump_sim::baseline::experiment::{score, Scores, Trace};
use pump_sim::sfm3300::raw_to_flow;
use ridge_core::control::Limits;
use ridge_core::{ArxModel, MapTable};
use ridge_pump_firmware::event::{Event, LINE_MAX};
use ridge_pump_firmware::lines::{MapLine, ParsedLine, PrintedModel, ReidLine};
use ridge_pump_firmware::reid::Reid;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::{value, Program, Setpoint, VolumeBreath};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_SCALE, SLM_PER_COUNT};
use ridge_pump_firmware::ventilation::Ventilation;

/// What a bench observed, in its own time unit (simavr: core cycles; stm32: ps).
pub struct RunInput<'a> {
    /// Every line: when its first byte left the UART, and its text.
    pub lines: Vec<(u64, &'a str)>,
    /// When each loop tick started, in order.
    pub ticks: Vec<u64>,
    /// Time units per second.
    pub per_s: f64,
    /// Every frame the sensor served: when, the raw word, the true flow then (slm).
    pub frames: Vec<(u64, u16, f64)>,
    /// The duty on the pump's pin at a time, 0..1.
    pub duty_at: &'a dyn Fn(u64) -> f64,
    /// The true flow near a time, slm (for ticks without a frame: a sensor fault).
    pub flow_at: &'a dyn Fn(u64) -> f64,
    /// The bench's time now.
    pub now: u64,
    /// Every change of the exhalation valve's pin: when, and `true` for closed.
    pub valve: Vec<(u64, bool)>,
    /// The breath settings of a `VENT` command the run was sent, if any.
    pub vent: Option<VolumeBreath>,
}

/// One row of the per-tick trace of a whole session (`--trace` CSV).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceRow {
    /// Tick start, seconds since reset.
    pub t: f64,
    /// The program's setpoint for the interval starting at this tick, slm; `None` before run
    /// mode.
    pub setpoint: Option<f64>,
    /// Duty on the pump pin during the interval starting at this tick, 0..1.
    pub duty: f64,
    /// True flow at the end of the interval (at the next tick's reading), slm.
    pub flow: f64,
    /// Breaths the valve started so far (closings of the exhalation valve), 0 before the first.
    pub breath: usize,
    /// `Some(true)` when the valve was closed during the interval (inspiration), `Some(false)`
    /// when open after the first breath started (expiration), `None` before it.
    pub phase: Option<bool>,
}

/// Run mode rebuilt from a bench (see the module docs).
#[derive(Clone, Debug)]
pub struct RunTrace {
    /// Bench tick index of run tick 0.
    pub first_tick: usize,
    /// When run tick 0 started, in the bench's time unit.
    pub first_at: u64,
    /// The start flow the program holds first, slm.
    pub start: f64,
    /// Setpoint preview from the `CTRL` line, ticks.
    pub preview: u32,
    /// The run-mode trace (one entry per complete interval).
    pub trace: Trace,
    /// Every tick of the session, for the CSV.
    pub rows: Vec<TraceRow>,
    /// `TRACK` lines checked against the rebuilt trace.
    pub track_lines: usize,
    /// Largest difference between a `TRACK` line's `sp=` / `flow=` and the same means from
    /// the rebuilt trace, slm (0.0005 is the printing's rounding).
    pub track_mismatch: f64,
    /// `TRACK` lines whose `tick=` disagreed with the first one's alignment.
    pub misaligned: usize,
    /// The controller's duty limits (fractions), for plots.
    pub limits: Limits<f64>,
    /// The run tick the volume program started at ([`RunInput::vent`]), if any.
    pub vent_tick: Option<usize>,
    /// The replayed volume program's `BREATH` events (what the firmware must have printed) and,
    /// when the firmware printed `REID` lines, its re-identification's `REID` events
    /// ([`reid_replay`]).
    pub replayed: Vec<Event>,
}

/// The program run mode tracks: the firmware's default settings' (the image's `Config`).
pub fn program() -> Program {
    DEFAULT_CONFIG.control.program
}

/// The most a tick's `v` (the map's flow at the duty, slm) can differ between the firmware
/// (duty in 1/`DUTY_FULL_SCALE`) and a replay that reads the duty back from a pin of `steps`
/// steps a period: the map's largest rise over half a pin step. The RMS of a window of them
/// differs by no more (`|RMS(a) − RMS(b)| ≤ max |a − b|`): [`RunTrace::reid_check`]'s
/// tolerance.
pub fn v_rms_unit(table: &MapTable, steps: u32) -> f64 {
    let half = (f64::from(DUTY_FULL_SCALE) / (2.0 * f64::from(steps.max(1)))).ceil();
    let half = half.min(f64::from(DUTY_FULL_SCALE)) as u16;
    (0..=DUTY_FULL_SCALE - half)
        .map(|u| i32::from(table.at(u + half)) - i32::from(table.at(u)))
        .max()
        .map_or(0.0, |d| f64::from(d) * f64::from(SLM_PER_COUNT))
}

impl RunTrace {
    /// Rebuilds run mode from what a bench observed (see the module docs); an error says what
    /// is missing (no `CTRL` line, no `TRACK` lines, no ticks).
    pub fn rebuild(input: &RunInput<'_>) -> Result<Self, String> {
        let ctrl = input
            .lines
            .iter()
            .find(|(_, t)| t.starts_with("CTRL"))
            .ok_or("no CTRL line: the controller was not designed")?;
        let preview = ParsedLine::parse(ctrl.1)
            .int("preview")
            .and_then(|p| u32::try_from(p).ok())
            .ok_or("CTRL line without preview=")?;
        let ticks = &input.ticks;
        if ticks.len() < 2 {
            return Err("no ticks".into());
        }
        let tick_of = |at: u64| ticks.partition_point(|&t| t <= at).checked_sub(1);
        // (bench tick of emission, tick=, sp, flow) of every TRACK line.
        let mut tracks = Vec::new();
        for &(at, text) in input.lines.iter().filter(|(_, t)| t.starts_with("TRACK")) {
            let p = ParsedLine::parse(text);
            let (Some(n), Some(sp), Some(flow)) = (p.int("tick"), p.num("sp"), p.num("flow"))
            else {
                return Err(format!("unreadable TRACK line: {text}"));
            };
            let j = tick_of(at).ok_or("TRACK line before the first tick")?;
            tracks.push((j, n, sp, flow));
        }
        let &(j1, n1, sp1, _) = tracks.first().ok_or("no TRACK line")?;
        let first_tick = usize::try_from(j1 as i64 - (n1 - 1))
            .map_err(|_| "TRACK tick= before the session started")?;
        let misaligned = tracks
            .iter()
            .filter(|&&(j, n, _, _)| j as i64 - (n - 1) != first_tick as i64)
            .count();
        // The first window lies within the hold: its mean setpoint is the start flow, a whole
        // number of counts (as the firmware holds its reading).
        let counts = (sp1 * f64::from(FLOW_SCALE)).round();
        let start = f64::from(counts as f32 * SLM_PER_COUNT);
        // The reading of each bench tick: the first frame served within it.
        let frames = &input.frames;
        let frame_of = |j: usize| -> Option<(u16, f64)> {
            let from = *ticks.get(j)?;
            let to = ticks.get(j + 1).copied().unwrap_or(u64::MAX);
            let i = frames.partition_point(|f| f.0 < from);
            frames
                .get(i)
                .filter(|f| f.0 < to)
                .map(|&(_, raw, flow)| (raw, flow))
        };
        let duty_of = |j: usize| -> f64 {
            let end = ticks.get(j + 1).copied().unwrap_or(input.now);
            (input.duty_at)(end.saturating_sub(1))
        };
        // The setpoint of every run tick: the program's, and from the valve's first closing
        // the volume program replayed on the readings.
        let program = program();
        let run_ticks = ticks.len().saturating_sub(first_tick);
        let mut sp: Vec<f64> = (0..run_ticks)
            .map(|k| f64::from(value(program, start as f32, k as u32)))
            .collect();
        let mut vent_tick = None;
        let mut replayed = Vec::new();
        if let Some(b) = input.vent {
            let closed = input
                .valve
                .iter()
                .find(|(_, closed)| *closed)
                .ok_or("VENT sent, but the valve never closed")?;
            let j = tick_of(closed.0).ok_or("valve closed before the first tick")?;
            // The program started a lead-in (one expiration) before the valve first closed.
            let lead = usize::from(b.wave.period() - b.wave.inspiration());
            let k0 = j
                .checked_sub(first_tick + lead)
                .ok_or("valve closed before run mode")?;
            vent_tick = Some(k0);
            let reading = |k: usize| frame_of(first_tick + k).map(|(raw, _)| raw_to_counts(raw));
            let mut held = (0..=k0).rev().find_map(reading).unwrap_or(0);
            let mut ended = k0.checked_sub(1).map_or(start, |k| sp[k]) as f32;
            let mut setpoint = Setpoint::new(Program::Volume(b), ended);
            let mut v = Ventilation::new(b.tidal);
            let mut reid = reid_replay(input, b)?;
            for (k, slot) in sp.iter_mut().enumerate().skip(k0) {
                let (_, phase) = setpoint.volume_phase().ok_or("not a volume program")?;
                let r = setpoint.advance();
                *slot = f64::from(r);
                if let Some(y) = reading(k) {
                    held = y;
                }
                let mut event = None;
                v.after_pwm(&mut setpoint, phase, held, ended, &mut event);
                if let Some(e @ Event::Breath(_)) = event {
                    replayed.push(e);
                }
                // As the firmware: not in the lead-in, from breath 1's first tick.
                if let Some((reid, table)) = reid.as_mut().filter(|_| v.breath() > 0) {
                    // The duty of the interval that ended with this tick's reading, as the
                    // firmware commanded it (the pin's fraction, back in 1/10 000).
                    let applied = (duty_of((first_tick + k).saturating_sub(1))
                        * f64::from(DUTY_FULL_SCALE))
                    .round() as u16;
                    let boundary = (phase == 0).then(|| v.breath());
                    reid.after_pwm(table.at(applied), held, boundary, false, v.alarm());
                    if let Some(report) = reid.take_report() {
                        replayed.push(Event::Reid(report));
                    }
                }
                ended = r;
            }
        }
        let sp_at = |k: usize| sp.get(k).copied().unwrap_or(f64::NAN);
        // The valve during each interval (its state at the interval's end) and the breaths
        // started by then.
        let valve_of = |j: usize| -> (usize, Option<bool>) {
            let end = ticks.get(j + 1).copied().unwrap_or(input.now);
            let before = input.valve.iter().take_while(|(at, _)| *at < end);
            let n = before.clone().filter(|(_, closed)| *closed).count();
            let closed = before.last().is_some_and(|(_, closed)| *closed);
            (n, (n > 0).then_some(closed))
        };

        let mut rows = Vec::with_capacity(ticks.len());
        let mut trace = Trace::default();
        for (j, &t) in ticks.iter().enumerate() {
            let next = frame_of(j + 1);
            let flow = next.map_or_else(
                || (input.flow_at)(ticks.get(j + 1).copied().unwrap_or(0)),
                |f| f.1,
            );
            let setpoint = (j >= first_tick).then(|| sp_at(j - first_tick));
            let (breath, phase) = valve_of(j);
            rows.push(TraceRow {
                t: t as f64 / input.per_s,
                setpoint,
                duty: duty_of(j),
                flow,
                breath,
                phase,
            });
            // Complete intervals only (the next tick's reading exists).
            if let (Some(sp), Some((raw, _))) = (setpoint, next) {
                if j + 1 < ticks.len() {
                    trace.setpoint.push(sp);
                    trace.flow.push(flow);
                    trace.measured.push(raw_to_flow(raw));
                    trace.duty.push(
                        (duty_of(j) * f64::from(DUTY_FULL_SCALE))
                            .round()
                            .clamp(0.0, f64::from(DUTY_FULL_SCALE)) as u16,
                    );
                }
            }
        }

        // Recompute every TRACK window: pairs (setpoint of interval i − 1, reading at run tick
        // i) for i in the window, the first pair with the start flow.
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
        let c = &DEFAULT_CONFIG.control;
        let frac = |d: u16| f64::from(d) / f64::from(DUTY_FULL_SCALE);
        Ok(RunTrace {
            first_tick,
            first_at: ticks[first_tick.min(ticks.len() - 1)],
            start,
            preview,
            trace,
            rows,
            track_lines: tracks.len(),
            track_mismatch: mismatch,
            misaligned,
            limits: Limits {
                min: frac(c.duty_min),
                max: frac(c.duty_max),
                max_step: frac(c.duty_step),
            },
            vent_tick,
            replayed,
        })
    }

    /// Whether the firmware's `TRACK` figures are those of the flow it was served: at least 10
    /// lines checked, none further than 0.002 slm from the rebuilt means (the printing's
    /// rounding is 0.0005), none misaligned; `Err` gives the three figures.
    pub fn track_check(&self) -> Result<(), String> {
        if self.track_lines < 10 || self.track_mismatch > 0.002 || self.misaligned > 0 {
            return Err(format!(
                "TRACK lines {} (≥ 10), recomputed difference {:.4} slm (≤ 0.002), misaligned {}",
                self.track_lines, self.track_mismatch, self.misaligned
            ));
        }
        Ok(())
    }

    /// Whether the replay's `REID` lines are the device's (`device`, parsed from its
    /// transcript): as many, and pair by pair the same breath and verdict, the gain within
    /// 0.002 (twice the printed digit), the fits within what the replay's running model (the
    /// `LOADED` line's 6 decimals) moves them (0.5 points, or 0.5 % of `100 − fit`: a fit's
    /// error scales with its residuals), the window's `v` RMS within `v_rms_unit` slm (what the
    /// duty read back from the board's pin moves it: [`v_rms_unit`]). Prints each pair; `Err`
    /// names the first that differs.
    pub fn reid_check(&self, device: &[ReidLine], v_rms_unit: f64) -> Result<(), String> {
        let host = self
            .replayed
            .iter()
            .filter(|e| matches!(e, Event::Reid(_)))
            .map(|e| {
                let line = e.line::<LINE_MAX>();
                ReidLine::parse(line.as_str()).map_err(|e| format!("replayed REID: {e:?}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        for (h, d) in host.iter().zip(device) {
            println!(
                "REID breath {:2}: host {} {:.3} {:.1}/{:.1} {:.3}, device {} {:.3} {:.1}/{:.1} {:.3}",
                h.breath, h.verdict, h.gain, h.fit, h.running, h.v_rms,
                d.verdict, d.gain, d.fit, d.running, d.v_rms
            );
        }
        if host.len() != device.len() {
            return Err(format!(
                "{} REID lines replayed, {} on the device",
                host.len(),
                device.len()
            ));
        }
        let fit_unit = |fit: f64| 0.5f64.max(0.005 * (100.0 - fit).abs());
        let near =
            |a: f64, b: f64, unit: f64| (a.is_nan() && b.is_nan()) || (a - b).abs() <= unit + 1e-9;
        match host.iter().zip(device).find(|(h, d)| {
            !(h.breath == d.breath
                && h.verdict == d.verdict
                && near(h.gain, d.gain, 0.002)
                && near(h.fit, d.fit, fit_unit(d.fit))
                && near(h.running, d.running, fit_unit(d.running))
                && near(h.v_rms, d.v_rms, v_rms_unit))
        }) {
            Some((h, d)) => Err(format!("host {h:?}\ndevice {d:?}")),
            None => Ok(()),
        }
    }

    /// The run's scores (steps, breaths, duty variation) from the true flow, as
    /// `pump_sim::baseline` scores its host runs; `None` when run mode was shorter than the
    /// demo program's scored part (`pump_sim::baseline::experiment::run_ticks`).
    pub fn scores(&self) -> Option<Scores> {
        score(&self.trace, false, self.preview)
    }

    /// Writes the per-tick CSV `t,setpoint,duty,flow,breath,phase` (seconds since reset, slm
    /// or empty before run mode, duty 0..1, true flow in slm, breaths the valve started so far
    /// (0 before the first), `i` in inspiration, `e` in expiration, empty before the first
    /// breath).
    pub fn write_csv(&self, path: &Path) -> Result<(), String> {
        let err = |e: std::io::Error| format!("{}: {e}", path.display());
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(err)?;
        }
        let mut w = std::io::BufWriter::new(std::fs::File::create(path).map_err(err)?);
        writeln!(w, "t,setpoint,duty,flow,breath,phase").map_err(err)?;
        for r in &self.rows {
            let sp = r.setpoint.map_or_else(String::new, |v| format!("{v:.4}"));
            let phase = match r.phase {
                Some(true) => "i",
                Some(false) => "e",
                None => "",
            };
            writeln!(
                w,
                "{:.5},{sp},{:.5},{:.4},{},{phase}",
                r.t, r.duty, r.flow, r.breath
            )
            .map_err(err)?;
        }
        w.flush().map_err(err)
    }
}

/// The re-identification of run mode (`ridge_pump_firmware::reid`, the firmware's own code)
/// replayed beside the volume program when the firmware printed `REID` lines: the running
/// model from the last `LOADED` or `ID` line before `CTRL` (6 decimals: the held-out fits may
/// differ in the last printed digit), the map from the last `MAP` line, the default settings,
/// one breath of `b` held out. With the window fed the bench's readings and the map's flow at
/// the pin's duty, and a re-estimate started at every breath boundary (the default
/// `ReidConfig::every` of 1 makes the drift and alarm triggers irrelevant), it prints what the
/// firmware must have printed. `None` without `REID` lines.
///
/// Errors: `REID` lines, but no model or map line to replay them from.
#[allow(clippy::type_complexity)]
pub fn reid_replay(
    input: &RunInput<'_>,
    b: VolumeBreath,
) -> Result<Option<(Reid, MapTable)>, String> {
    if !input.lines.iter().any(|(_, t)| t.starts_with("REID")) {
        return Ok(None);
    }
    let ctrl = input
        .lines
        .iter()
        .position(|(_, t)| t.starts_with("CTRL"))
        .ok_or("REID lines without a CTRL line")?;
    let before = &input.lines[..ctrl];
    let model_line = before
        .iter()
        .rev()
        .find(|(_, t)| t.starts_with("LOADED ") || t.starts_with("ID "))
        .ok_or("REID lines without a LOADED or ID line")?;
    let printed = PrintedModel::from_line(&ParsedLine::parse(model_line.1))
        .map_err(|e| format!("{}: {e}", model_line.1))?;
    let f = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let model = ArxModel::<f32>::new(
        &f(&printed.theta),
        &f(&printed.phi),
        printed.d,
        printed.offset,
        printed.c as f32,
    )
    .map_err(|e| format!("{}: {e:?}", model_line.1))?;
    let map_line = before
        .iter()
        .rev()
        .find(|(_, t)| t.starts_with("MAP "))
        .ok_or("REID lines without a MAP line")?;
    let map = MapLine::parse(map_line.1).map_err(|e| format!("{}: {e}", map_line.1))?;
    let reid = DEFAULT_CONFIG.reidentification(model, u32::from(b.wave.period()));
    Ok(Some((reid, map.map.table())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ridge_core::InputMap;

    #[test]
    fn v_rms_unit_is_the_steepest_segment_over_half_a_pin_step() {
        // 100 counts a knot (600 duty units apart), but 1 000 between knots 7 and 8.
        let mut knots = [0i16; 16];
        for (k, v) in knots.iter_mut().enumerate() {
            *v = 100 * k as i16 + if k >= 8 { 900 } else { 0 };
        }
        let table = InputMap::new(0, 600, knots).expect("map").table();
        // 800 steps: half a step is 10 000 / 1 600 = 6.25 duty units, taken as 7; on the steep
        // segment 7 · 1 000 / 600 = 11.7 counts (the map rounds down: 11 or 12).
        let unit = v_rms_unit(&table, 800) / f64::from(SLM_PER_COUNT);
        assert!((11.0 - 1e-6..=12.0 + 1e-6).contains(&unit), "{unit}");
        // 5 000 steps: 1 duty unit, 1 000 / 600 = 1.7 counts: 1 or 2.
        let unit = v_rms_unit(&table, 5000) / f64::from(SLM_PER_COUNT);
        assert!((1.0 - 1e-6..=2.0 + 1e-6).contains(&unit), "{unit}");
    }
}
