//! What `stm32-run` prints from a session: the firmware's lines, the model with its host
//! rerun, the validation, the design and run mode's `TRACK` lines, instructions per control
//! tick, of the search and of the design, flash and RAM. In one file so that the board-
//! independent report `simavr-harness` prints can take its place once both share it.

use std::fmt::Write as _;

use ridge_id::capture::{classify, Kind};

use crate::bench::secs;
use crate::machine::CPI;
use crate::session::{self, IdLine, Outcome};

/// Target instructions per control tick (0.1 ms at 100 MHz, issue 30).
pub const TICK_TARGET: u64 = 10_000;

fn show_model(m: &IdLine) -> String {
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.6}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        "(p, q, d) = ({}, {}, {})  theta = [{}]  phi = [{}]  c = {:.4}",
        m.p,
        m.q,
        m.d,
        list(&m.theta),
        list(&m.phi),
        m.c
    )
}

fn ms(ps: u64) -> f64 {
    ps as f64 / 1e9
}

/// The report of `out` (`all_lines`: every line, log rows too). Returns the text and whether
/// the run identified an accepted model without a fault.
pub fn render(out: &Outcome, all_lines: bool) -> (String, bool) {
    let mut s = String::new();
    let bench = &out.bench;
    let _ = writeln!(
        s,
        "firmware lines{}:",
        if all_lines {
            ""
        } else {
            " (events; log rows left out)"
        }
    );
    for l in &bench.lines {
        if all_lines || (l.keyword() != "RES" && classify(l.text.as_bytes()) != Kind::Row) {
            let _ = writeln!(s, "  [{:8.3} s] {}", secs(l.start), l.text);
        }
    }
    let m = &bench.machine;
    let sim = bench.time_s();
    let resets = m.resets.len().saturating_sub(1);
    let _ = writeln!(
        s,
        "\nemulated {sim:.2} s in {:.2} s wall ({:.1}x real time), {} instructions, {:.2} s of polling skipped by the clock jump{}",
        out.wall_s,
        sim / out.wall_s.max(1e-9),
        m.instructions(),
        secs(m.core().jumped),
        if resets > 0 {
            format!(", {resets} reset(s): {:?}", &m.resets[1..])
        } else {
            String::new()
        }
    );
    let misses = &m.chip().misses;
    if !misses.is_empty() {
        let _ = writeln!(s, "  unmodelled accesses: {misses:?}");
    }
    if !m.faults.is_empty() {
        let _ = writeln!(s, "  CPU faults: {:?}", m.faults);
    }
    let mut ok = misses.is_empty();

    let _ = writeln!(
        s,
        "\n== identified model (ID line: dynamics from the map's flow to the flow, slm/slm)"
    );
    if let Some(map) = &out.map {
        let flows: Vec<String> = map
            .knots()
            .iter()
            .map(|k| format!("{:.1}", f64::from(*k) / 120.0))
            .collect();
        let _ = writeln!(
            s,
            "  map (MAP line): duty {:.2} % + k x {:.2} % -> flow [{}] slm",
            f64::from(map.first()) / 100.0,
            f64::from(map.step()) / 100.0,
            flows.join(", ")
        );
    }
    match &out.id {
        Some(id) => {
            let _ = writeln!(s, "  {}", show_model(id));
            if let Some((e, n)) = id.eval {
                let _ = writeln!(s, "  candidates evaluated {e} of {n} (exact pruning)");
            }
        }
        None => {
            let _ = writeln!(s, "  none");
            ok = false;
        }
    }
    match (&out.id, &out.estimation) {
        (Some(id), Some(est)) => {
            for (name, host) in [
                ("f64", session::host_search::<f64>(est)),
                (
                    "f32, as the firmware computes",
                    session::host_search::<f32>(est),
                ),
            ] {
                let text = match host {
                    Ok(h) => match session::coefficient_error(id, &h) {
                        Some(e) => format!("same structure, max coefficient difference {e:.2e}"),
                        None => format!("DIFFERENT: {}", show_model(&h)),
                    },
                    Err(e) => format!("failed: {e}"),
                };
                let _ = writeln!(
                    s,
                    "  host rerun ({name}; IntGram + Search on the {} samples served): {text}",
                    est.len()
                );
            }
        }
        (Some(_), None) => {
            let _ = writeln!(
                s,
                "  (estimation record could not be rebuilt from the logs)"
            );
        }
        _ => {}
    }

    let _ = writeln!(s, "\n== validation");
    match &out.accept {
        Some(a) => {
            let _ = writeln!(
                s,
                "  firmware: ACCEPT free-run fit {} %, rmse {} slm, one-step rmse {} slm",
                a.get("fit").unwrap_or("?"),
                a.get("rmse").unwrap_or("?"),
                a.get("one").unwrap_or("?")
            );
        }
        None => ok = false,
    }
    for r in &out.rejects {
        let _ = writeln!(s, "  firmware: REJECT {:?}", r.fields);
    }

    let _ = writeln!(s, "\n== flow control");
    match bench.find("CTRL").next() {
        Some(l) => {
            let _ = writeln!(s, "  firmware: {}", l.text);
        }
        None => {
            let _ = writeln!(s, "  no CTRL line");
        }
    }
    let tracks: Vec<_> = bench.find("TRACK").collect();
    if let Some(last) = tracks.last() {
        let _ = writeln!(s, "  {} TRACK lines; last: {}", tracks.len(), last.text);
    }

    let t = &out.timing;
    let hz = m.chip().clocks().hclk;
    let _ = writeln!(
        s,
        "\n== instructions (HCLK {} MHz, {CPI} cycle per instruction assumed; tick = 10 ms)",
        hz / 1_000_000
    );
    let _ = writeln!(
        s,
        "  control (tick start -> TIM3_CCR1 written: sensor read, state machine, PWM) over {} ticks: mean {:.0}, worst {} instructions (target {TICK_TARGET}); worst {:.3} ms emulated incl. the I2C transfer",
        t.ticks,
        t.control_mean,
        t.control_worst,
        ms(t.control_worst_ps)
    );
    let _ = writeln!(
        s,
        "  whole tick (to the idle wait, incl. report lines): mean {:.0}, worst {} instructions",
        t.tick_mean, t.tick_worst
    );
    match (t.search_instr, t.search_ps) {
        (Some(i), Some(p)) => {
            let _ = writeln!(
                s,
                "  search: {i} instructions, {:.1} ms emulated (incl. {} ticks run inside it)",
                ms(p),
                t.search_ticks.map_or("?".into(), |n| n.to_string())
            );
        }
        _ => {
            let _ = writeln!(s, "  search: n/a");
        }
    }
    match (t.design_instr, t.design_ps) {
        (Some(i), Some(p)) => {
            let _ = writeln!(s, "  design: {i} instructions, {:.1} ms emulated", ms(p));
        }
        _ => {
            let _ = writeln!(s, "  design: n/a");
        }
    }
    for f in &out.faults {
        let _ = writeln!(s, "  FAULT {} {:?}", f.words.join(" "), f.fields);
        ok = false;
    }

    let z = out.sizes;
    let _ = writeln!(
        s,
        "\n== flash and RAM\n  flash {} B (text {} + data {}) of the image's 256 KB (sectors 0-5; 6 and 7 hold the record); static RAM {} B (data {} + bss {}) of 128 KB; stack high-water {} B (measured: RAM below the stack top no longer holding the power-up pattern)",
        z.flash(),
        z.text,
        z.data,
        z.ram(),
        z.data,
        z.bss,
        out.bench
            .machine
            .stack_used()
            .map_or_else(|| "n/a".to_string(), |b| b.to_string())
    );
    (s, ok)
}
