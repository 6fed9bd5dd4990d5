//! One plant and seed identified both ways, scored ([`run`]), and the markdown of
//! `powerup-table` ([`markdown`]).

use std::fmt::Write;

use ridge_pump_firmware::event::{Event, LINE_MAX};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::selfid::{Config, SelfIdentification, State};
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::SLM_PER_COUNT;

use super::before::{model_before, BEFORE_RECORD};
use super::fits::{breaths, free_run_fit, fresh_ramp, Against, PumpModel};
use super::spectrum::{bands, Bands};
use super::verdicts::{verdict_before, verdict_now, Change, Verdict};
use crate::{Blower, Outlet, PlantArgs, Sfm3300Params, TS_S};

/// Noise seed of the fresh B-Ramp's measured flow, added to the identification's.
pub const FRESH_SEED: u64 = 1_000;

/// The figures of one plant and seed.
#[derive(Debug, Clone)]
pub struct Case {
    /// Blower and outlet.
    pub plant: PlantArgs,
    /// Sensor noise seed of the identification.
    pub seed: u64,
    /// Ticks from power-up to `ACCEPT` on the host, where the search takes no time.
    pub accept_ticks: u32,
    /// The model and its structure `(p, q, d)`.
    pub now: PumpModel,
    /// The model before issue 31.
    pub before: PumpModel,
    /// Free-run fits (%) over the breaths against the true flow: now, before.
    pub breaths: [f32; 2],
    /// Free-run fits (%) on the fresh B-Ramp against the true flow: now, before.
    pub ramp_true: [f32; 2],
    /// The same against the measured flow (fresh noise): now, before.
    pub ramp_measured: [f32; 2],
    /// The firmware's validation fit (its `ACCEPT` line), percent.
    pub validation: f32,
    /// The estimation record's duties as applied (now).
    pub record: Vec<u16>,
}

/// Runs the firmware's power-up identification on `plant` with noise `seed` (host, the state
/// machine of `config`) to `ACCEPT` and run mode; then scores it and the model before.
pub fn run(plant: &PlantArgs, seed: u64, config: &'static Config) -> Result<Case, String> {
    let mut rig = plant.rig(Sfm3300Params::default(), seed)?;
    let mut sm = SelfIdentification::new(config, None);
    let (mut duty, mut accept, mut validation) = (0u16, None, f32::NAN);
    let mut record = Vec::new();
    let mut events = Vec::new();
    for tick in 0..20_000u32 {
        let before = sm.state();
        let t = sm.tick(Ok(raw_to_counts(rig.step(duty))));
        if before == State::Excite {
            record.push(duty);
        }
        duty = t.duty;
        let mut evs: Vec<Event> = t.event.into_iter().collect();
        evs.extend(sm.judge());
        evs.extend(sm.search(|| {}));
        evs.extend(sm.design(|| {}));
        for e in evs {
            if let Event::Accepted { fit, .. } = e {
                accept.get_or_insert(tick);
                validation = fit;
            }
            events.push(e.line::<LINE_MAX>().as_str().to_owned());
        }
        match sm.state() {
            State::Run => break,
            State::Fault => return Err(events.join(" | ")),
            _ => {}
        }
    }
    let (Some(accept_ticks), Some(model), Some(map)) = (accept, sm.model(), sm.map()) else {
        return Err(events.join(" | "));
    };
    let now = PumpModel {
        model: *model,
        map: Some(*map),
    };
    let before = PumpModel {
        model: model_before(plant, seed)?,
        map: None,
    };
    let (b, b0) = breaths(plant)?;
    let (r, r0) = fresh_ramp();
    let fit = |m: &PumpModel, d: &[u16], s: u16, a: Against| free_run_fit(plant, m, d, s, a);
    let fresh = Against::Measured(seed + FRESH_SEED);
    Ok(Case {
        plant: plant.clone(),
        seed,
        accept_ticks,
        breaths: [
            fit(&now, &b, b0, Against::TrueFlow)?,
            fit(&before, &b, b0, Against::TrueFlow)?,
        ],
        ramp_true: [
            fit(&now, &r, r0, Against::TrueFlow)?,
            fit(&before, &r, r0, Against::TrueFlow)?,
        ],
        ramp_measured: [fit(&now, &r, r0, fresh)?, fit(&before, &r, r0, fresh)?],
        now,
        before,
        validation,
        record,
    })
}

/// The spectrum of the estimation record of `case` and of the record before issue 31, both
/// as the flow they ask through the case's map, against its blower's corner frequency
/// `1 / (2π τ_up)`.
pub fn spectra(case: &Case) -> Option<(Bands, Bands, f64)> {
    let map = case.now.map?;
    let flow = |d: &u16| f64::from(map.at(*d)) * f64::from(SLM_PER_COUNT);
    let f_c = 1.0 / (2.0 * std::f64::consts::PI * case.plant.pump().tau_up_s);
    let rate = 1.0 / TS_S;
    let now: Vec<f64> = case.record.iter().map(flow).collect();
    let before: Vec<f64> = BEFORE_RECORD.generator().map(|d| flow(&d)).collect();
    Some((bands(&now, rate, f_c), bands(&before, rate, f_c), f_c))
}

/// The nine presets.
pub fn presets() -> Vec<PlantArgs> {
    let mut v = Vec::new();
    for b in [Blower::Default, Blower::Sluggish, Blower::Small] {
        for o in Outlet::ALL {
            v.push(PlantArgs::preset(b, o));
        }
    }
    v
}

/// The changes of the plant the verdicts are taken on (see [`super::verdicts`]).
pub fn changes() -> Vec<Change> {
    vec![
        Change::None,
        Change::Flow(0.5),
        Change::Flow(0.7),
        Change::Flow(1.4),
        Change::Lag(3.0),
        Change::Delay(4),
        Change::Lung(crate::LungParams::stiff()),
    ]
}

fn name(p: &PlantArgs) -> String {
    format!("{} {}", p.plant.name(), p.lung.name())
}

/// The markdown of `powerup-table`: the fits table, the spectra and the verdicts.
pub fn markdown(cases: &[Case], verdicts: &[(String, Change, Verdict, Verdict)]) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "| blower, outlet | seed | ready (host, s) | model (p, q, d) | breaths: now / before, % | \
         B-Ramp true flow: now / before, % | B-Ramp measured: now / before, % | validation, % |"
    );
    let _ = writeln!(o, "|---|---:|---:|---|---:|---:|---:|---:|");
    for c in cases {
        let s = c.now.model.structure();
        let _ = writeln!(
            o,
            "| {} | {} | {:.2} | ({}, {}, {}) | {:.1} / {:.1} | {:.1} / {:.1} | {:.1} / {:.1} | {:.1} |",
            name(&c.plant),
            c.seed,
            f64::from(c.accept_ticks) * TS_S,
            s.p,
            s.q,
            s.d,
            c.breaths[0],
            c.breaths[1],
            c.ramp_true[0],
            c.ramp_true[1],
            c.ramp_measured[0],
            c.ramp_measured[1],
            c.validation
        );
    }
    let min = |f: &dyn Fn(&Case) -> f32| cases.iter().map(f).fold(f32::INFINITY, f32::min);
    let _ = writeln!(
        o,
        "\nLowest: breaths {:.1} % now ({:.1} % before); B-Ramp true flow {:.1} % ({:.1} %), \
         measured {:.1} % ({:.1} %); validation {:.1} %.",
        min(&|c| c.breaths[0]),
        min(&|c| c.breaths[1]),
        min(&|c| c.ramp_true[0]),
        min(&|c| c.ramp_true[1]),
        min(&|c| c.ramp_measured[0]),
        min(&|c| c.ramp_measured[1]),
        min(&|c| c.validation)
    );
    let _ = writeln!(
        o,
        "\n| blower, outlet | f_c, Hz | record | samples | variance, slm² | below f_c/4 | \
         f_c/4 .. 4 f_c | above 4 f_c | band power, slm² |"
    );
    let _ = writeln!(o, "|---|---:|---|---:|---:|---:|---:|---:|---:|");
    for c in cases.iter().filter(|c| c.seed == cases[0].seed) {
        if let Some((now, before, f_c)) = spectra(c) {
            for (what, b) in [
                ("flow steps (now)", now),
                (Record::AMultistep.name(), before),
            ] {
                let _ = writeln!(
                    o,
                    "| {} | {:.2} | {} | {} | {:.0} | {:.0} % | {:.0} % | {:.0} % | {:.0} |",
                    name(&c.plant),
                    f_c,
                    what,
                    b.samples,
                    b.variance,
                    100.0 * b.fractions[0],
                    100.0 * b.fractions[1],
                    100.0 * b.fractions[2],
                    b.band_power()
                );
            }
        }
    }
    let _ = writeln!(
        o,
        "\n| blower, outlet | change at validation | before: fit %, verdict | now: fit %, verdict |"
    );
    let _ = writeln!(o, "|---|---|---:|---:|");
    let word = |v: &Verdict| if v.accepted { "accepted" } else { "refused" };
    for (plant, change, before, now) in verdicts {
        let _ = writeln!(
            o,
            "| {plant} | {} | {:.1} {} | {:.1} {} |",
            change.name(),
            before.fit,
            word(before),
            now.fit,
            word(now)
        );
    }
    let count = |f: &dyn Fn(&Verdict, &Verdict) -> bool| {
        verdicts.iter().filter(|(_, _, b, n)| f(b, n)).count()
    };
    let _ = writeln!(
        o,
        "\nConfusion (rows before, columns now): accepted/accepted {}, accepted/refused {}, \
         refused/accepted {}, refused/refused {}.",
        count(&|b, n| b.accepted && n.accepted),
        count(&|b, n| b.accepted && !n.accepted),
        count(&|b, n| !b.accepted && n.accepted),
        count(&|b, n| !b.accepted && !n.accepted)
    );
    o
}

/// The verdicts of both rules on every preset's blower (open outlet and its lungs) for every
/// [`changes`] entry, noise seed `seed`.
pub fn all_verdicts(
    plants: &[PlantArgs],
    seed: u64,
    config: &'static Config,
) -> Result<Vec<(String, Change, Verdict, Verdict)>, String> {
    let mut out = Vec::new();
    for p in plants {
        for change in changes() {
            // A lung appearing behind an outlet that has one already changes nothing new.
            if matches!(change, Change::Lung(_)) && p.lung != Outlet::Open {
                continue;
            }
            let before = verdict_before(p, seed, &change, config.min_fit)?;
            let now = verdict_now(p, seed, &change, config)?;
            out.push((name(p), change, before, now));
        }
    }
    Ok(out)
}
