//! The ventilation benchmark on the ATmega2560 image (issue 32, *Targets*): what
//! `pump_sim::vent_bench` measures on the host, run on the whole image in simavr with the
//! controller the firmware runs there (the power-up design, frozen: this board has no
//! re-identification), scored with the host bench's own rules
//! ([`pump_sim::vent_bench::score`], [`pump_sim::vent_bench::change_verdict`]) on the
//! simulated lung's truth.
//!
//! One [`Case`] is one ISO 80601-2-12 row's breath with one inspiratory wave, optionally with a
//! sudden change of the lung ([`Change`]); [`run_case`] powers the image up into the case's
//! (first) lung with its PEEP valve at 0 (the firmware identifies and designs its controller,
//! ~17 s of simulated time; or loads [`stored_model`] and designs), sends the row's `VENT`
//! line ([`vent_line`]: `ti` 1 s, the row's PEEP, trim on, default bias and rise) as
//! [`crate::ventilation::run`] does, runs the breaths and turns each into the host bench's
//! [`Breath`] (the lung's truth, the firmware's `BREATH` figures beside it).

use pump_sim::baseline::experiment::identify_with;
use pump_sim::iso::IsoRow;
use pump_sim::vent_bench::{power_up_plant, Breath, CellRun, ChangeAt, CHANGE_BREATH, CHANGE_RUN};
use pump_sim::LungParams;
use ridge_pump_firmware::persist::RECORD_LEN;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::Shape;
use ridge_pump_firmware::slots::{self, STORE_LEN};

use crate::bench::LungChange;
use crate::session::SessionConfig;
use crate::ventilation::{self, VentConfig, VentOutcome};

/// A sudden change of the lung.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Change {
    /// Compliance and resistance from the change on, mL/cmH₂O and cmH₂O/(L/s).
    pub to: (f64, f64),
    /// The breath (from 1) in which it happens.
    pub breath: u32,
    /// At its boundary (the valve closing) or half-way through its inspiration.
    pub at: ChangeAt,
}

/// One run's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    /// The ISO row: its breath, PEEP and (unless [`Case::lung`] says otherwise) lung.
    pub row: IsoRow,
    /// The lung at power-up `(C, R)`, mL/cmH₂O and cmH₂O/(L/s) (the row's by default).
    pub lung: (f64, f64),
    /// Inspiratory flow shape.
    pub wave: Shape,
    /// Breaths scored.
    pub breaths: u32,
    /// A lung change, if any.
    pub change: Option<Change>,
    /// Sensor-noise seed.
    pub seed: u64,
    /// Start from a stored model ([`stored_model`]: identified on the host's rig) instead of
    /// the image's own power-up identification.
    pub stored: bool,
}

impl Case {
    /// `row`'s lung and breath with `wave`, `breaths` breaths, no change, seed 1.
    pub fn row(row: IsoRow, wave: Shape, breaths: u32) -> Self {
        Case {
            row,
            lung: (row.compliance, row.resistance),
            wave,
            breaths,
            change: None,
            seed: 1,
            stored: false,
        }
    }

    /// Row 1's breath (square) on the lung `from`, changed to `to` in breath
    /// [`CHANGE_BREATH`] of [`CHANGE_RUN`] at `at`: the host's lung-change cell.
    pub fn change(row1: IsoRow, from: (f64, f64), to: (f64, f64), at: ChangeAt) -> Self {
        Case {
            lung: from,
            change: Some(Change {
                to,
                breath: CHANGE_BREATH,
                at,
            }),
            ..Case::row(row1, Shape::Square, CHANGE_RUN)
        }
    }

    /// The power-up lung: the case's C and R behind the adult exhalation valve, the row's PEEP.
    pub fn power_up_lung(&self) -> LungParams {
        LungParams {
            compliance: self.lung.0,
            resistance: self.lung.1,
            ..self.row.lung(&LungParams::adult())
        }
    }
}

/// The EEPROM contents (offset, bytes) holding `record` in the first slot of an empty store,
/// as the firmware writes it.
pub fn eeprom_with(record: &[u8; RECORD_LEN]) -> Result<Vec<(u16, Vec<u8>)>, String> {
    let (at, bytes) = slots::slot_bytes(record, &slots::plan(&[0xFF; STORE_LEN]))
        .ok_or("the record does not fit a slot")?;
    Ok(vec![(at, bytes.to_vec())])
}

/// A stored model for `lung`: the firmware's state machine (compiled for the host) identifies
/// it on `pump_sim`'s rig with sensor seed `seed` and the host benchmark's power-up plant
/// ([`power_up_plant`]: `lung` with its PEEP valve at 0); the image loads it at reset and runs
/// within ~2 s instead of identifying for ~17 s. EEPROM contents as [`eeprom_with`].
pub fn stored_model(lung: &LungParams, seed: u64) -> Result<Vec<(u16, Vec<u8>)>, String> {
    let (_, sm, _) =
        identify_with(&power_up_plant(lung), seed, &DEFAULT_CONFIG).map_err(|e| e.to_string())?;
    eeprom_with(
        &sm.persist_bytes()
            .ok_or("no model after the identification")?,
    )
}

/// The console line of `row`'s breath with `wave`: `VENT vt=… rate=… ti=1 wave=… peep=…
/// trim=on` (the host bench's settings, `pump_sim::vent_bench::vent_settings`, as a line).
pub fn vent_line(row: &IsoRow, wave: Shape) -> String {
    let wave = match wave {
        Shape::Square => "square",
        Shape::Ramp => "ramp",
    };
    format!(
        "VENT vt={} rate={} ti={} wave={wave} peep={} trim=on",
        row.tidal,
        row.rate,
        row.ti(),
        row.peep
    )
}

/// One run's result.
#[derive(Debug)]
pub struct CaseRun {
    /// The breaths as the host bench scores them ([`cell_run`]).
    pub run: CellRun,
    /// The answer to `VENT`.
    pub answer: Option<String>,
    /// `FAULT` and `PANIC` lines.
    pub faults: Vec<String>,
    /// `DRIFT` lines after `OK vent`.
    pub drifts: usize,
    /// Missed ticks (overruns) over the whole run.
    pub missed: usize,
    /// Worst control tick (tick ISR entry → PWM written) from `OK vent` on, cycles.
    pub worst_tick: Option<u64>,
    /// Wall-clock time of the simulation, s.
    pub wall_s: f64,
}

impl CaseRun {
    /// Largest |firmware `vd` − lung| over the breaths, mL (NaN if no breath was reported).
    pub fn firmware_gap(&self) -> f64 {
        self.run
            .breaths
            .iter()
            .map(|b| (b.measured_ml - b.delivered_ml).abs())
            .fold(f64::NAN, f64::max)
    }
}

/// The breaths 1 to `breaths` of `out` as the host bench scores them: the lung's truth, the
/// firmware's `vd` / `cmd` in `measured_ml` / `command_ml` (NaN without its `BREATH` line),
/// `end_pressure` the lung's at the next closing (NaN if none came), `rms` NaN (not scored
/// here).
pub fn cell_run(out: &VentOutcome, breaths: u32) -> CellRun {
    let set = f64::from(out.breath.tidal);
    let peep = f64::from(out.breath.peep);
    let breaths = out
        .rows
        .iter()
        .filter(|r| r.number <= breaths as usize)
        .map(|r| Breath {
            number: r.number as u32,
            set_ml: set,
            delivered_ml: r.truth.delivered,
            measured_ml: r.firmware.as_ref().map_or(f64::NAN, |l| l.delivered),
            command_ml: r.firmware.as_ref().map_or(f64::NAN, |l| l.command),
            peak_pressure: r.truth.peak_pressure,
            end_pressure: r.peep_after.unwrap_or(f64::NAN),
            start_pressure: r.truth.peep,
            peep,
            rms: f64::NAN,
        })
        .collect();
    CellRun {
        breaths,
        estimates: Vec::new(),
        designs: Vec::new(),
    }
}

/// Runs `case` on the image `elf` (see the [module docs](self)).
pub fn run_case(elf: &std::path::Path, case: &Case) -> Result<CaseRun, String> {
    let command = vent_line(&case.row, case.wave);
    let breath = ventilation::parse_vent(&command)?;
    let lung = case.power_up_lung();
    let mut session = SessionConfig::new(elf);
    session.bench.lung = Some(lung.clone());
    session.bench.seed = case.seed;
    if case.stored {
        session.bench.eeprom = stored_model(&lung, case.seed)?;
    }
    let period = f64::from(breath.wave.period()) * 0.01;
    let ti = f64::from(breath.wave.inspiration()) * 0.01;
    // The power-up (~17 s), the lead-in, the breaths and one more closing, with a margin.
    session.max_s = 60.0 + period * f64::from(case.breaths + 3);
    let change = case.change.map(|c| {
        let delay = match c.at {
            ChangeAt::Boundary => 0.0,
            ChangeAt::Mid => 0.5 * ti,
        };
        let to = LungChange {
            compliance: Some(c.to.0),
            resistance: Some(c.to.1),
            ..LungChange::default()
        };
        (c.breath as usize, delay, to)
    });
    let cfg = VentConfig {
        session,
        command,
        identify_peep: 0.0,
        peep: lung.peep,
        // One breath more than scored: the last scored breath's end-expiratory pressure is
        // the lung's at the next closing.
        breaths: case.breaths + 1,
        change,
    };
    let out = ventilation::run(&cfg)?;
    let bench = &out.outcome.bench;
    let vent = bench.lines.iter().position(|l| l.text == "OK vent");
    let from = vent.map_or(u64::MAX, |i| bench.line_starts[i]);
    let worst_tick = bench
        .ticks()
        .iter()
        .filter(|t| t.start >= from)
        .filter_map(|t| t.control)
        .max();
    let drifts = vent.map_or(0, |i| {
        bench.lines[i..]
            .iter()
            .filter(|l| l.text.starts_with("DRIFT"))
            .count()
    });
    Ok(CaseRun {
        run: cell_run(&out, case.breaths),
        answer: out.answer,
        faults: bench
            .lines
            .iter()
            .filter(|l| l.text.starts_with("FAULT") || l.text == "PANIC")
            .map(|l| l.text.clone())
            .collect(),
        drifts,
        missed: out.outcome.timing.missed,
        worst_tick,
        wall_s: out.outcome.wall_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pump_sim::iso::ISO_ROWS;
    use pump_sim::vent_bench::vent_settings;

    /// The line the bench sends sets what the host bench runs, row by row and wave by wave
    /// (the firmware's parser and checks on one side, the host's `VentArgs` on the other).
    #[test]
    fn the_vent_line_sets_the_host_benchs_breath() {
        for row in &ISO_ROWS {
            for wave in [Shape::Square, Shape::Ramp] {
                let line = ventilation::parse_vent(&vent_line(row, wave)).expect("line");
                let host = vent_settings(row, wave, true).expect("host");
                assert_eq!(line, host, "row {} {wave:?}", row.row);
            }
        }
    }
}
