//! A ventilated session: the firmware identifies the pump at power-up into the test lung (its
//! exhalation valve open, the lung venting through the PEEP valve), designs its controller,
//! and once run mode has started the bench does what an operator does: sets the PEEP valve
//! and sends `VENT …` over the console. The firmware then drives the valve and the breaths;
//! the session runs for a number of breaths (with a sudden change of the lung at a chosen
//! breath, if asked) and pairs each breath as the lung saw it ([`BreathTruth`]) with the
//! firmware's `BREATH` line.
//!
//! The PEEP valve during the identification is a setting of its own
//! ([`VentConfig::identify_peep`]): the power-up identification drives the blower from 20 %
//! to 90 % duty with the valve open, and at a PEEP of 10 cmH₂O its 40 % steps cannot open the
//! PEEP valve (the blower's shut-off pressure there is 10.1 cmH₂O): the stall check stops the
//! pump (`FAULT stall`). The default identifies with the PEEP valve at 0 and sets the row's
//! PEEP with the `VENT` command, as an operator sets the PEEP valve when ventilation starts.

use std::time::Instant;

use ridge_pump_firmware::command::{self, Command};
use ridge_pump_firmware::lines::BreathLine;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::VolumeBreath;
use ridge_pump_firmware::ventilation;

use crate::bench::{Action, Bench, BreathTruth, LungChange, RunEnd};
use crate::firmware;
use crate::session::{self, Outcome, SessionConfig};
use crate::transcript::Line;

/// What to run.
#[derive(Clone, Debug)]
pub struct VentConfig {
    /// The bench (its lung with the identification's PEEP) and the time limit.
    pub session: SessionConfig,
    /// The console line that starts ventilation (`VENT vt=… rate=…`, without `\n`).
    pub command: String,
    /// The PEEP valve setting while the firmware identifies, cmH₂O.
    pub identify_peep: f64,
    /// The PEEP valve setting from the `VENT` command on, cmH₂O.
    pub peep: f64,
    /// Breaths to run (`BREATH` lines to wait for).
    pub breaths: u32,
    /// A sudden change of the lung: at breath `.0` (from 1), `.1` s after its valve closed.
    pub change: Option<(usize, f64, LungChange)>,
}

/// One breath: the lung's truth and the firmware's line.
#[derive(Clone, Debug)]
pub struct BreathRow {
    /// Breath number, from 1.
    pub number: usize,
    /// The lung's truth (delivered volume, peak pressure, PEEP before it).
    pub truth: BreathTruth,
    /// End-expiratory lung pressure after the breath (at the next closing), cmH₂O.
    pub peep_after: Option<f64>,
    /// Inspiratory time the valve was closed, s.
    pub closed_s: Option<f64>,
    /// The firmware's `BREATH n=` line, if printed.
    pub firmware: Option<BreathLine>,
}

/// A ventilated session's result.
#[derive(Debug)]
pub struct VentOutcome {
    /// The session's figures (identification, timing, sizes, lines).
    pub outcome: Outcome,
    /// The settings the firmware took (parsed from the command with the firmware's code).
    pub breath: VolumeBreath,
    /// The answer to `VENT` (`OK vent` / `ERR …`), if one came.
    pub answer: Option<String>,
    /// Breath by breath.
    pub rows: Vec<BreathRow>,
}

/// The settings `line` gives with the firmware's own parser and checks.
pub fn parse_vent(line: &str) -> Result<VolumeBreath, String> {
    match command::parse(line.as_bytes()) {
        Ok(Command::Vent(args)) => ventilation::settings(&args, DEFAULT_CONFIG.flow_limit)
            .map_err(|e| format!("{line}: out of range: {e}")),
        Ok(_) => Err(format!("{line}: not a VENT command")),
        Err(e) => Err(format!("{line}: {}", e.name())),
    }
}

/// Runs a ventilated session (see the [module docs](self)).
pub fn run(cfg: &VentConfig) -> Result<VentOutcome, String> {
    let breath = parse_vent(&cfg.command)?;
    let bench_cfg = &cfg.session.bench;
    let sizes = firmware::sizes(&bench_cfg.elf)?;
    let mut bench = Bench::new(bench_cfg.clone())?;
    if cfg.session.log {
        bench.send_after(|_| true, 0.0, b"LOG on\n".to_vec());
    }
    if let Some(l) = &mut bench.lung {
        let p = LungChange {
            peep: Some(cfg.identify_peep),
            ..LungChange::default()
        }
        .apply(l.params());
        l.set_params(p);
    }
    let t0 = Instant::now();
    let max_s = cfg.session.max_s;
    let designed = |l: &Line| l.text.starts_with("CTRL") || l.text.starts_with("FAULT");
    let mut answer = None;
    if let RunEnd::Line(i) = bench.run_until(max_s, designed) {
        if bench.lines[i].text.starts_with("CTRL") {
            // A moment of run mode, then the operator sets the PEEP valve and sends VENT.
            bench.run_for(0.5);
            bench.apply(Action::Lung(LungChange {
                peep: Some(cfg.peep),
                ..LungChange::default()
            }));
            let from = bench.lines.len();
            bench.send_now(format!("{}\n", cfg.command));
            if let Some((k, delay, change)) = cfg.change {
                bench.at_breath(k, delay, Action::Lung(change));
            }
            let is_answer = |l: &Line| l.text.starts_with("OK vent") || l.text.starts_with("ERR");
            bench.run_until(max_s, is_answer);
            answer = bench.lines[from..]
                .iter()
                .find(|l| is_answer(l))
                .map(|l| l.text.clone());
            let last = format!("BREATH n={} ", cfg.breaths);
            let done = |l: &Line| {
                l.text.starts_with(&last) || l.text.starts_with("FAULT") || l.text == "PANIC"
            };
            if answer.as_deref() == Some("OK vent") {
                bench.run_until(max_s, done);
                // The valve's next closing and the line after it.
                bench.run_for(0.2);
            }
        }
    }
    let wall = t0.elapsed().as_secs_f64();
    let outcome = session::analyse(bench, sizes, wall);
    let rows = rows(&outcome.bench);
    Ok(VentOutcome {
        outcome,
        breath,
        answer,
        rows,
    })
}

/// The breaths of `bench`: its truth paired with the firmware's `BREATH` lines by number.
pub fn rows(bench: &Bench) -> Vec<BreathRow> {
    let lines: Vec<BreathLine> = bench
        .find_lines("BREATH")
        .filter_map(|(_, l)| BreathLine::parse(&l.text).ok())
        .collect();
    let f = f64::from(bench.frequency());
    bench
        .breaths
        .iter()
        .enumerate()
        .map(|(i, t)| BreathRow {
            number: i + 1,
            truth: *t,
            peep_after: bench.breaths.get(i + 1).map(|n| n.peep),
            closed_s: t.open.map(|o| (o - t.start) as f64 / f),
            firmware: lines.iter().rfind(|l| l.number as usize == i + 1).cloned(),
        })
        .collect()
}

/// Whether `delivered` is within `±(4 mL + rel · set)` of `set` (mL): ISO 80601-2-12's band
/// with `rel` = 0.15, the target with 0.05.
pub fn within(delivered: f64, set: f64, rel: f64) -> bool {
    (delivered - set).abs() <= 4.0 + rel * set
}
