//! `--mode volume`: the flags of a ventilated run, the `VENT` line they make, and the
//! per-breath report (the lung's truth beside the firmware's `BREATH` lines).

use clap::{Args, ValueEnum};
use pump_sim::iso::iso_row;
use pump_sim::PlantArgs;
use ridge_pump_firmware::event::Event;
use simavr_harness::bench::LungChange;
use simavr_harness::session::TICK_CYCLES;
use simavr_harness::tracking;
use simavr_harness::ventilation::{within, BreathRow, VentOutcome};

/// What run mode does after the controller design.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Mode {
    /// The firmware's demo program (flow steps, then breath profiles).
    Flow,
    /// Volume-controlled breaths: `VENT` sent over the console once run mode started.
    Volume,
}

/// Inspiratory flow shape (`VENT wave=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Wave {
    /// Constant flow.
    Square,
    /// Decelerating ramp.
    Ramp,
}

/// Where in the breath a lung change happens.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ChangeAt {
    /// When the valve closes (the breath boundary).
    Boundary,
    /// Halfway through the inspiration.
    Mid,
}

/// The flags of `--mode volume` (the lung's C, R and PEEP are the plant's `--compliance`,
/// `--resistance`, `--peep`).
#[derive(Args, Clone, Debug)]
pub struct VentArgs {
    /// Run mode's program: the demo (`flow`) or volume-controlled breaths (`volume`).
    #[arg(long, value_enum, default_value = "flow")]
    pub mode: Mode,
    /// ISO 80601-2-12 Table 201.104 row 1-8: fills the lung (C, R, PEEP) and the breath
    /// (rate, inspiratory time, tidal volume) not given otherwise.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=8))]
    pub iso: Option<u8>,
    /// Tidal volume, mL.
    #[arg(long, value_name = "VT_ML")]
    pub tidal: Option<f64>,
    /// Breaths per minute.
    #[arg(long, value_name = "PER_MIN")]
    pub rate: Option<f64>,
    /// Inspiratory time, s (default: I:E 1:2).
    #[arg(long, value_name = "SECONDS")]
    pub ti: Option<f64>,
    /// Inspiratory flow shape.
    #[arg(long, value_enum, default_value = "square")]
    pub wave: Wave,
    /// Expiratory bias flow, slm (default: the firmware's, 5 slm).
    #[arg(long, value_name = "SLM")]
    pub bias: Option<f64>,
    /// The per-breath volume trim (`VENT trim=`).
    #[arg(long, value_enum, default_value = "on")]
    pub trim: OnOff,
    /// Breaths to run.
    #[arg(long, value_name = "N", default_value_t = 10)]
    pub breaths: u32,
    /// PEEP valve setting while the firmware identifies at power-up, cmH2O (the row's PEEP is
    /// set with VENT; today's identification stalls against a PEEP of 10).
    #[arg(long, value_name = "CMH2O", default_value_t = 0.0)]
    pub identify_peep: f64,
    /// Breath (from 1) at which the lung changes suddenly.
    #[arg(long, value_name = "K")]
    pub change_breath: Option<usize>,
    /// The compliance from the change on, mL/cmH2O.
    #[arg(long, value_name = "C2")]
    pub change_compliance: Option<f64>,
    /// The airway resistance from the change on, cmH2O/(L/s).
    #[arg(long, value_name = "R2")]
    pub change_resistance: Option<f64>,
    /// A leak from the change on: its resistance, cmH2O/(L/s).
    #[arg(long, value_name = "R_LEAK")]
    pub change_leak: Option<f64>,
    /// When in the breath the change happens.
    #[arg(long, value_enum, default_value = "boundary")]
    pub change_at: ChangeAt,
}

/// `on` / `off`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OnOff {
    /// On.
    On,
    /// Off.
    Off,
}

/// A number as the console takes it: at most 3 decimals, no exponent.
fn num(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

impl VentArgs {
    /// Fills the plant's lung from `--iso` where the flags left it open.
    pub fn fill_plant(&self, plant: &mut PlantArgs) -> Result<(), String> {
        if let Some(n) = self.iso {
            let r = iso_row(n).ok_or(format!("no ISO row {n}"))?;
            plant.compliance.get_or_insert(r.compliance);
            plant.resistance.get_or_insert(r.resistance);
            plant.peep.get_or_insert(r.peep);
        }
        Ok(())
    }

    /// The `VENT` line of these flags with the lung's PEEP `peep` (cmH2O).
    pub fn command(&self, peep: f64) -> Result<String, String> {
        let row = self.iso.and_then(iso_row);
        let tidal = self
            .tidal
            .or(row.map(|r| r.tidal))
            .ok_or("--mode volume needs --tidal (or --iso)")?;
        let rate = self
            .rate
            .or(row.map(|r| r.rate))
            .ok_or("--mode volume needs --rate (or --iso)")?;
        let mut line = format!("VENT vt={} rate={}", num(tidal), num(rate));
        if let Some(ti) = self.ti.or(row.map(|r| r.ti())) {
            line += &format!(" ti={}", num(ti));
        }
        line += match self.wave {
            Wave::Square => " wave=square",
            Wave::Ramp => " wave=ramp",
        };
        line += &format!(" peep={}", num(peep));
        if let Some(b) = self.bias {
            line += &format!(" bias={}", num(b));
        }
        line += match self.trim {
            OnOff::On => " trim=on",
            OnOff::Off => " trim=off",
        };
        Ok(line)
    }

    /// The lung change asked for: `(breath, delay after its closing in s, change)`; the
    /// delay of `mid` is half the inspiratory time `ti` (s).
    pub fn change(&self, ti: f64) -> Result<Option<(usize, f64, LungChange)>, String> {
        let change = LungChange {
            compliance: self.change_compliance,
            resistance: self.change_resistance,
            peep: None,
            leak: self.change_leak,
        };
        match self.change_breath {
            None if change != LungChange::default() => {
                Err("--change-compliance/-resistance/-leak need --change-breath".into())
            }
            None => Ok(None),
            Some(0) => Err("--change-breath counts from 1".into()),
            Some(k) => {
                let delay = match self.change_at {
                    ChangeAt::Boundary => 0.0,
                    ChangeAt::Mid => 0.5 * ti,
                };
                Ok(Some((k, delay, change)))
            }
        }
    }
}

/// Prints the ventilation section; `false` when the firmware did not ventilate as asked.
pub fn print(out: &VentOutcome, command: &str, breaths: u32) -> bool {
    let bench = &out.outcome.bench;
    let b = &out.breath;
    let w = &b.wave;
    println!("\n== ventilation (volume control; `VENT` sent over the console in run mode)");
    println!(
        "  command: {command}  ->  answer: {}",
        out.answer.as_deref().unwrap_or("none")
    );
    println!(
        "  the firmware's program: period {} ticks, inspiration {} ticks (valve closed), rise {} ticks, {:?}, bias {} slm, peak {:.3} slm for {} mL, PEEP {} cmH2O, trim {}",
        w.period(),
        w.inspiration(),
        w.rise(),
        w.shape(),
        w.bias(),
        w.bias() + w.amplitude(),
        b.tidal,
        b.peep,
        if b.trim { "on" } else { "off" }
    );
    let mut ok = out.answer.as_deref() == Some("OK vent");
    let rows: Vec<&BreathRow> = out
        .rows
        .iter()
        .filter(|r| r.number as u32 <= breaths)
        .collect();
    println!(
        "  per breath (lung = the simulator's truth: volume gained while the valve was closed, peak airway pressure, end-expiratory pressure after the breath, peak flow while the valve was closed; fw = the firmware's BREATH line):"
    );
    println!(
        "    {:>3} {:>6} {:>8} {:>8} {:>7} {:>8} {:>8} {:>7} {:>7} {:>8} {:>8} {:>7}",
        "n",
        "Ti s",
        "lung mL",
        "fw vd",
        "err %",
        "fw cmd",
        "Ppeak",
        "PEEP",
        "dPpeak",
        "lung pk",
        "fw peak",
        "fw rms"
    );
    let set = f64::from(b.tidal);
    let mut prev_peak: Option<f64> = None;
    for r in &rows {
        let t = &r.truth;
        let fw = r.firmware.as_ref();
        let dp = prev_peak.map_or(String::from("-"), |p| {
            format!("{:+.1}", t.peak_pressure - p)
        });
        prev_peak = Some(t.peak_pressure);
        println!(
            "    {:>3} {:>6} {:>8.1} {:>8} {:>+7.1} {:>8} {:>8.1} {:>7} {:>7} {:>8.2} {:>8} {:>7}",
            r.number,
            r.closed_s.map_or("-".into(), |s| format!("{s:.3}")),
            t.delivered,
            fw.map_or("-".into(), |l| format!("{:.1}", l.delivered)),
            100.0 * (t.delivered - set) / set,
            fw.map_or("-".into(), |l| format!("{:.1}", l.command)),
            t.peak_pressure,
            r.peep_after.map_or("-".into(), |p| format!("{p:.2}")),
            dp,
            t.peak_flow,
            fw.map_or("-".into(), |l| format!("{:.2}", l.peak)),
            fw.map_or("-".into(), |l| format!("{:.2}", l.rms)),
        );
    }
    let scored: Vec<&&BreathRow> = rows.iter().filter(|r| r.number >= 3).collect();
    if !scored.is_empty() {
        let n = scored.len();
        let in15 = scored
            .iter()
            .filter(|r| within(r.truth.delivered, set, 0.15))
            .count();
        let in5 = scored
            .iter()
            .filter(|r| within(r.truth.delivered, set, 0.05))
            .count();
        let worst = scored
            .iter()
            .map(|r| 100.0 * (r.truth.delivered - set) / set)
            .fold(0.0f64, |a, e| if e.abs() > a.abs() { e } else { a });
        let peep_err = scored
            .iter()
            .filter_map(|r| r.peep_after)
            .map(|p| p - f64::from(b.peep))
            .fold(0.0f64, |a, e| if e.abs() > a.abs() { e } else { a });
        println!(
            "  breaths 3-{}: delivered (lung) within ±(4 mL + 15 %) {in15}/{n}, within ±(4 mL + 5 %) {in5}/{n}, worst error {worst:+.1} %; PEEP (lung, end of expiration) worst {peep_err:+.2} cmH2O from the set {}",
            rows.len(),
            b.peep
        );
    }
    if rows.len() < breaths as usize {
        println!("  only {} of {breaths} breaths ran", rows.len());
        ok = false;
    }
    match tracking::run_trace_ventilated(bench, *b) {
        Ok(run) => {
            let same = run
                .replayed
                .iter()
                .filter_map(|e| match e {
                    Event::Breath(s) => Some(s),
                    _ => None,
                })
                .zip(rows.iter().filter_map(|r| r.firmware.as_ref()))
                .all(|(s, l)| {
                    (f64::from(s.delivered) - l.delivered).abs() <= 0.051
                        && (f64::from(s.command) - l.command).abs() <= 0.051
                });
            println!(
                "  the firmware's volumes replayed on the host from the frames it was served (its own code): {} ({} breaths); TRACK lines recomputed: largest difference {:.4} slm, {} misaligned",
                if same { "equal" } else { "DIFFERENT" },
                run.replayed.len().min(rows.len()),
                run.track_mismatch,
                run.misaligned
            );
            let from = run
                .vent_tick
                .map_or(u64::MAX, |k| bench.ticks()[run.first_tick + k].start);
            let control: Vec<u64> = bench
                .ticks()
                .iter()
                .filter(|t| t.start >= from)
                .filter_map(|t| t.control)
                .collect();
            if let Some(&worst) = control.iter().max() {
                println!(
                    "  control tick while ventilating (ISR -> PWM written) over {} ticks: worst {} cycles ({:.3} ms), mean {:.3} ms; budget 1.6 ms (tick {TICK_CYCLES} cycles)",
                    control.len(),
                    worst,
                    worst as f64 / 16_000.0,
                    control.iter().sum::<u64>() as f64 / control.len() as f64 / 16_000.0
                );
            }
        }
        Err(e) => {
            println!("  no ventilation trace: {e}");
            ok = false;
        }
    }
    ok
}
