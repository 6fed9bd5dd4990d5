//! The tables of `avr-vent-bench`: per run the host benchmark's figures (worst volume error
//! from breath 3, the bands, breath 1, the peak pressure's rise on the breath before, the PEEP
//! error; after a change the breaths until back in the bands) on the lung's truth, the
//! firmware's own `BREATH` volumes beside them, and the run's health (faults, `DRIFT` lines,
//! overruns, the worst control tick).

use pump_sim::vent_bench::{change_verdict, score, ChangeAt};
use ridge_pump_firmware::setpoint::Shape;
use simavr_harness::vent_bench::{Case, CaseRun};

/// The name of the wave `w`.
fn wave_name(w: Shape) -> &'static str {
    match w {
        Shape::Square => "square",
        Shape::Ramp => "ramp",
    }
}

/// Faults, `DRIFT` lines, overruns, the worst control tick (cycles) of `r`.
fn health(r: &CaseRun) -> String {
    let mut s = String::new();
    if r.answer.as_deref() != Some("OK vent") {
        s += &format!("answer {:?}; ", r.answer);
    }
    if !r.faults.is_empty() {
        s += &format!("{}; ", r.faults.join(", "));
    }
    s += &format!(
        "{} DRIFT, {} overruns, tick {}",
        r.drifts,
        r.missed,
        r.worst_tick.map_or("-".into(), |c| c.to_string())
    );
    s
}

/// Whether `r` ran its breaths without a fault; prints why not.
fn ran(what: &str, r: &Result<CaseRun, String>, breaths: u32) -> bool {
    match r {
        Err(e) => {
            println!("{what}: {e}");
            false
        }
        Ok(r) if r.run.breaths.len() < breaths as usize || !r.faults.is_empty() => {
            println!(
                "{what}: {} of {breaths} breaths; {}",
                r.run.breaths.len(),
                health(r)
            );
            false
        }
        Ok(_) => true,
    }
}

/// Prints `r`'s breaths.
fn breaths(what: &str, r: &CaseRun) {
    println!("\n{what}: n, lung mL (error %), firmware vd / cmd mL, peak pressure, PEEP after");
    for b in &r.run.breaths {
        println!(
            "  {:2} {:6.1} ({:+5.1} %)  fw {:6.1} / {:6.1}  {:5.1}  {:5.2}",
            b.number,
            b.delivered_ml,
            b.error_pct(),
            b.measured_ml,
            b.command_ml,
            b.peak_pressure,
            b.end_pressure
        );
    }
}

/// Prints the rows table; `false` if a run failed.
pub fn rows(cases: &[Case], runs: &[Result<CaseRun, String>], per_breath: bool) -> bool {
    let mut ok = true;
    println!(
        "## ATmega2560 in simavr: ISO rows, frozen power-up controller, trim on, seed {}{}\n",
        cases.first().map_or(1, |c| c.seed),
        if cases.first().is_some_and(|c| c.stored) {
            ", from a stored model identified on the host's rig"
        } else {
            ""
        }
    );
    println!(
        "| row | wave | worst \\|error\\| breaths ≥ 3 (%) | ±(4 mL + 5 %) from 3 | ±(4 mL + 15 %) from 3 | breath 1 error (%) | lung at breath 1's start − PEEP (cmH₂O) | peak pressure rise on the breath before, max: breaths ≥ 3 / breath 2 (cmH₂O) | \\|PEEP error\\| max (cmH₂O) | firmware vd: worst \\|error\\| ≥ 3 (%), max \\|vd − lung\\| (mL) | DRIFT, overruns, worst control tick (cycles) | wall (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (c, r) in cases.iter().zip(runs) {
        let what = format!("row {} {}", c.row.row, wave_name(c.wave));
        if !ran(&what, r, c.breaths) {
            ok = false;
            continue;
        }
        let Ok(r) = r else { continue };
        let s = score(&r.run, 3);
        let b = &r.run.breaths;
        let fw_worst = b
            .iter()
            .filter(|b| b.number >= 3)
            .map(|b| (100.0 * (b.measured_ml - b.set_ml) / b.set_ml).abs())
            .fold(f64::NAN, f64::max);
        let n = b.iter().filter(|b| b.number >= 3).count();
        let count = |rel: f64| b.iter().filter(|b| b.number >= 3 && b.within(rel)).count();
        println!(
            "| {} | {} | {:.1} | {}/{n} | {}/{n} | {:+.1} | {:+.2} | {:+.1} / {:+.1} | {:.2} | {:.1}, {:.1} | {}, {}, {} | {:.0} |",
            c.row.row,
            wave_name(c.wave),
            s.worst_pct,
            count(0.05),
            count(0.15),
            b[0].error_pct(),
            b[0].start_pressure - b[0].peep,
            s.peak_rise,
            b[1].peak_pressure - b[0].peak_pressure,
            s.peep_err,
            fw_worst,
            r.firmware_gap(),
            r.drifts,
            r.missed,
            r.worst_tick.map_or("-".into(), |c| c.to_string()),
            r.wall_s
        );
    }
    println!();
    if per_breath {
        for (c, r) in cases.iter().zip(runs) {
            if let Ok(r) = r {
                breaths(&format!("row {} {}", c.row.row, wave_name(c.wave)), r);
            }
        }
        println!();
    }
    ok
}

/// Prints the lung-change table; `false` if a run failed.
pub fn changes(named: &[(&str, Case)], runs: &[Result<CaseRun, String>], per_breath: bool) -> bool {
    let mut ok = true;
    let Some(first) = named.first().map(|(_, c)| c) else {
        return true;
    };
    let at_breath = first.change.map_or(0, |c| c.breath);
    println!(
        "## ATmega2560 in simavr: lung changes on row 1's breath (500 mL, 20 /min, Ti 1 s, PEEP 5, square, trim on), {} the first lung, change in breath {at_breath} of {}, seed {}\n",
        if first.stored {
            "a stored model identified on the host's rig in"
        } else {
            "power-up into"
        },
        first.breaths,
        first.seed
    );
    println!("Counts from the change breath (= 1): the last breath outside the band (0: none).\n");
    println!(
        "| change | at | last outside ±(4 mL + 15 %) | last outside ±(4 mL + 5 %) | worst breath error (%) | targets: 15 % by 2nd, 5 % by 4th, none beyond 35 % | peak pressure vs previous breath, max (cmH₂O) | peak pressure before → after (cmH₂O) | \\|PEEP error\\| max (cmH₂O) | max \\|firmware vd − lung\\| (mL) | DRIFT, overruns, worst control tick (cycles) | wall (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for ((name, c), r) in named.iter().zip(runs) {
        let Some(ch) = c.change else { continue };
        let at = match ch.at {
            ChangeAt::Boundary => "boundary",
            ChangeAt::Mid => "mid-inspiration",
        };
        if !ran(&format!("{name} {at}"), r, c.breaths) {
            ok = false;
            continue;
        }
        let Ok(r) = r else { continue };
        let v = change_verdict(&r.run, ch.breath);
        let s = score(&r.run, ch.breath);
        let before = r
            .run
            .breaths
            .iter()
            .find(|b| b.number + 1 == ch.breath)
            .map_or(f64::NAN, |b| b.peak_pressure);
        let mark = |b: bool| if b { "yes" } else { "no" };
        println!(
            "| {name} | {at} | {} | {} | {:.1} | {} / {} / {} | {:+.1} | {:.1} → {:.1} | {:.2} | {:.1} | {}, {}, {} | {:.0} |",
            v.last15,
            v.last5,
            v.worst_pct,
            mark(v.meets15()),
            mark(v.meets5()),
            mark(v.meets35()),
            s.peak_rise,
            before,
            v.peak_pressure,
            s.peep_err,
            r.firmware_gap(),
            r.drifts,
            r.missed,
            r.worst_tick.map_or("-".into(), |c| c.to_string()),
            r.wall_s
        );
    }
    println!();
    if per_breath {
        for ((name, c), r) in named.iter().zip(runs) {
            if let (Ok(r), Some(ch)) = (r, c.change) {
                breaths(&format!("{name} {:?}", ch.at), r);
            }
        }
        println!();
    }
    ok
}
