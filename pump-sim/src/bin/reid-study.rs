//! Prints the closed-loop re-identification study (issue 32 item 3; docs/control.md,
//! "Closed-loop re-identification"): the true plant's linearisations, the re-estimates against
//! them with and without a dither, the direct method's bias against the window length and the
//! noise, and the adaptive controller against the frozen one across a lung change.
//!
//! ```text
//! cargo run --release -p pump-sim --bin reid-study
//! cargo run --release -p pump-sim --bin reid-study -- --seeds 10
//! ```
//!
//! The computations live in `pump_sim::reid`; this binary only runs them and prints.

use clap::Parser;
use pump_sim::reid::{
    self, breaths_in, linearisation, mean_sd, model_step, models_in, rise63, secant_gain,
    secant_through_map, step_error_pct, through_map, Dither, Linearisation, Mode, Study, StudyRun,
};
use ridge_core::RidgeM;

/// Runs the study and prints its tables.
#[derive(Debug, Parser)]
#[command(name = "reid-study")]
struct Args {
    /// Noise seeds per configuration (1, 2, …).
    #[arg(long, default_value_t = 5)]
    seeds: u64,
}

/// The dither of the study: ±1 slm on the setpoint, 4 ticks per bit.
const DITHER: Dither = Dither {
    amplitude: 1.0,
    hold: 4,
};

/// Phases of the lung-change scenario: label, first breath, end breath, lung breath.
const PHASES: [(&str, u32, u32); 5] = [
    ("adult, breaths 1-9", 1, 10),
    ("C10 R50, breaths 10-13 (after the change)", 10, 14),
    ("C10 R50, breaths 20-29", 20, 30),
    ("adult again, breaths 30-33", 30, 34),
    ("adult again, breaths 40-49", 40, 50),
];

/// The re-estimates tabled: snapshot breaths `from..to` of each lung phase, from 4 (first
/// phase) or 10 breaths after its start (the window of `k` = 2 weighs the breath `b` back by
/// `(3/4)^b`: 6 % left of the old lung after 10 breaths) to a breath before the next change
/// (an estimate's hold-out runs into the next breath).
const ESTIMATED: [(&str, u32, u32); 3] = [
    ("adult, snapshots 4-8", 4, 9),
    ("C10 R50, snapshots 20-28", 20, 29),
    ("adult again, snapshots 40-48", 40, 49),
];

fn runs(study: &Study, seeds: u64) -> Vec<StudyRun> {
    (1..=seeds)
        .filter_map(|seed| {
            match reid::run(&Study {
                seed,
                ..study.clone()
            }) {
                Ok(r) => Some(r),
                Err(e) => {
                    eprintln!("seed {seed}: {e}");
                    None
                }
            }
        })
        .collect()
}

/// `base` with `mode`, `dither` and the paper's Ridge-M at `max_iter` iterates per re-estimate,
/// run at `max_iter / 200` units a tick (the paper's 200 iterates: one unit a tick).
fn at_iterates(base: &Study, mode: Mode, dither: Option<Dither>, max_iter: u32) -> Study {
    Study {
        mode,
        dither,
        method: RidgeM {
            max_iter,
            ..RidgeM::PAPER
        },
        units: max_iter / 200,
        ..base.clone()
    }
}

fn truth(study: &Study, breath: u32) -> [Linearisation; 3] {
    let lung = study.lung_at(breath);
    [10.0, 35.0, 60.0].map(|f| linearisation(&study.plant, &lung, f))
}

fn main() {
    let args = Args::parse();
    let base = Study::lung_change(1);
    let adult_duty = truth(&base, 0);
    let stiff_duty = truth(&base, 10);
    // The models are the dynamics after the power-up's static map (duty -> the map's flow):
    // the truth through seed 1's map.
    let Some(first) = runs(
        &Study {
            mode: Mode::Frozen,
            breaths: 1,
            ..base.clone()
        },
        1,
    )
    .pop() else {
        eprintln!("no power-up");
        std::process::exit(1);
    };
    let table = first.switchover.map.table();
    let adult = adult_duty.clone().map(|l| through_map(&l, &table));
    let stiff = stiff_duty.clone().map(|l| through_map(&l, &table));
    let secant = |t: &[Linearisation; 3]| {
        if std::ptr::eq(t, &adult) {
            secant_through_map(&adult_duty[0], &adult_duty[2], &table)
        } else {
            secant_through_map(&stiff_duty[0], &stiff_duty[2], &table)
        }
    };

    println!(
        "## Truth: the noise-free plant linearised (default blower; ±0.5 % duty steps), and \
         through the power-up's map (seed 1)"
    );
    println!();
    println!(
        "| lung | flow slm | duty % | gain slm/duty | gain through the map, slm/slm | 63 % rise, \
         ticks |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, t, v) in [
        ("C 50 R 5", &adult_duty, &adult),
        ("C 10 R 50", &stiff_duty, &stiff),
    ] {
        for (l, lv) in t.iter().zip(v.iter()) {
            println!(
                "| {name} | {:.0} | {:.2} | {:.1} | {:.3} | {} |",
                l.flow,
                100.0 * l.duty,
                l.gain,
                lv.gain,
                rise63(&l.step).map_or("-".into(), |r| r.to_string())
            );
        }
        println!(
            "| {name} | secant 10-60 | | {:.1} | {:.3} | |",
            secant_gain(&t[0], &t[2]),
            secant(v)
        );
    }

    println!();
    println!(
        "## Re-estimates of the frozen loop (observed, not swapped), {} seeds: static gain, 63 % \
         rise and step-response error against the truth at 35 slm, held-out free-run fit",
        args.seeds
    );
    println!();
    let pu: Vec<_> = runs(
        &Study {
            mode: Mode::Frozen,
            breaths: 1,
            ..base.clone()
        },
        args.seeds,
    )
    .iter()
    .map(|r| r.switchover.model)
    .collect();
    let pu_gain: Vec<f64> = pu.iter().map(|m| f64::from(m.static_gain())).collect();
    let pu_err: Vec<f64> = pu
        .iter()
        .map(|m| step_error_pct(&model_step(m, reid::STEP_TICKS), &adult[1].step))
        .collect();
    let pu_rise: Vec<f64> = pu
        .iter()
        .filter_map(|m| rise63(&model_step(m, reid::STEP_TICKS)).map(|r| r as f64))
        .collect();
    println!(
        "Power-up models (adult lung): gain {:.3} ± {:.3}, 63 % rise {:.1} ticks, step error {:.1} %.",
        mean_sd(&pu_gain).0,
        mean_sd(&pu_gain).1,
        mean_sd(&pu_rise).0,
        mean_sd(&pu_err).0
    );
    println!();
    println!(
        "| Ridge-M iterates | dither | phase | estimates | gain (mean ± sd) | secant | 63 % rise \
         (truth) | step error % | held-out fit % | window's input RMS, slm |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for max_iter in [200u32, 5000] {
        for dither in [None, Some(DITHER)] {
            let all = runs(
                &at_iterates(&base, Mode::Observe, dither, max_iter),
                args.seeds,
            );
            for (label, from, to) in ESTIMATED {
                let t = if (10..30).contains(&from) {
                    &stiff
                } else {
                    &adult
                };
                let models: Vec<_> = all.iter().flat_map(|r| models_in(r, from, to)).collect();
                let gains: Vec<f64> = models.iter().map(|m| f64::from(m.static_gain())).collect();
                let steps: Vec<_> = models
                    .iter()
                    .map(|m| model_step(m, reid::STEP_TICKS))
                    .collect();
                let errs: Vec<f64> = steps
                    .iter()
                    .map(|s| step_error_pct(s, &t[1].step))
                    .collect();
                let rises: Vec<f64> = steps
                    .iter()
                    .filter_map(|s| rise63(s).map(|r| r as f64))
                    .collect();
                let fits: Vec<f64> = all
                    .iter()
                    .flat_map(|r| r.estimates.iter())
                    .filter(|e| e.breath >= from && e.breath < to)
                    .filter_map(|e| match e.verdict {
                        Some(Ok((c, _))) => Some(f64::from(c)),
                        Some(Err(ridge_core::reid::Rejection::Fit { candidate, .. })) => {
                            Some(f64::from(candidate))
                        }
                        _ => None,
                    })
                    .collect();
                let duty: Vec<f64> = all
                    .iter()
                    .flat_map(|r| r.estimates.iter())
                    .filter(|e| e.breath >= from && e.breath < to)
                    .map(|e| f64::from(e.input_response))
                    .collect();
                let (g, gs) = mean_sd(&gains);
                println!(
                    "| {max_iter} | {} | {label} | {} | {g:.3} ± {gs:.3} | {:.3} | {:.1} ({}) | \
                     {:.1} | {:.1} | {:.1} |",
                    if dither.is_some() { "±1 slm" } else { "none" },
                    models.len(),
                    secant(t),
                    mean_sd(&rises).0,
                    rise63(&t[1].step).map_or("-".into(), |r| r.to_string()),
                    mean_sd(&errs).0,
                    mean_sd(&fits).0,
                    mean_sd(&duty).0,
                );
            }
        }
    }

    println!();
    println!(
        "## Without breaths: a constant 30 slm setpoint on the adult lung, frozen loop observed, \
         12 breaths' time, {} seeds, 5000 iterates; estimates from breath 6 on",
        args.seeds
    );
    println!();
    println!(
        "| dither | estimates | gain (mean ± sd) | truth at 35 slm | 63 % rise (truth) | window's \
         input RMS, slm | refused |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (label, dither) in [
        ("none", None),
        ("±1 slm, 4 ticks a bit", Some(DITHER)),
        (
            "±1 slm, 20 ticks a bit",
            Some(Dither {
                amplitude: 1.0,
                hold: 20,
            }),
        ),
    ] {
        let study = Study {
            mode: Mode::Observe,
            program: ridge_pump_firmware::setpoint::Program::Constant(30.0),
            breaths: 12,
            changes: Vec::new(),
            dither,
            method: RidgeM {
                max_iter: 5000,
                ..RidgeM::PAPER
            },
            units: 25,
            ..base.clone()
        };
        let all = runs(&study, args.seeds);
        let models: Vec<_> = all.iter().flat_map(|r| models_in(r, 6, 12)).collect();
        let gains: Vec<f64> = models.iter().map(|m| f64::from(m.static_gain())).collect();
        let rises: Vec<f64> = models
            .iter()
            .filter_map(|m| rise63(&model_step(m, reid::STEP_TICKS)).map(|r| r as f64))
            .collect();
        let refused = all
            .iter()
            .flat_map(|r| r.estimates.iter())
            .filter(|e| e.breath >= 6 && matches!(e.verdict, Some(Err(_))))
            .count();
        let duty: Vec<f64> = all
            .iter()
            .flat_map(|r| r.estimates.iter())
            .filter(|e| e.breath >= 6)
            .map(|e| f64::from(e.input_response))
            .collect();
        let (g, gs) = mean_sd(&gains);
        println!(
            "| {label} | {} | {g:.3} ± {gs:.3} | {:.3} | {:.1} ({}) | {:.2} | {refused} |",
            models.len(),
            adult[1].gain,
            mean_sd(&rises).0,
            rise63(&adult[1].step).map_or("-".into(), |r| r.to_string()),
            mean_sd(&duty).0,
        );
    }

    println!();
    println!(
        "## The direct method's bias: adult lung, frozen loop observed, 20 breaths, {} seeds; \
         gain of the estimates from breath 12 on against the noise-free plant's secant gain \
         ({:.1}) and against the noise-free sensor's estimate (x0: quantisation only)",
        args.seeds,
        secant(&adult)
    );
    println!();
    println!(
        "| Ridge-M iterates | window k (2^k breaths) | x0 | x1 | x3 | x6 | x1 vs secant % | x3 vs \
         secant % | x6 vs secant % |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let secant = secant(&adult);
    for max_iter in [200u32, 5000] {
        for shift in [1u8, 2, 3, 4] {
            let gain = |noise_x: f64| {
                let study = Study {
                    mode: Mode::Observe,
                    breaths: 20,
                    changes: Vec::new(),
                    shift,
                    noise_x,
                    method: RidgeM {
                        max_iter,
                        ..RidgeM::PAPER
                    },
                    units: max_iter / 100,
                    ..base.clone()
                };
                let g: Vec<f64> = runs(&study, args.seeds)
                    .iter()
                    .flat_map(|r| models_in(r, 12, 20))
                    .map(|m| f64::from(m.static_gain()))
                    .collect();
                mean_sd(&g).0
            };
            let g: Vec<f64> = [0.0, 1.0, 3.0, 6.0].iter().map(|&x| gain(x)).collect();
            let pct = |v: f64| 100.0 * (v - secant) / secant;
            println!(
                "| {max_iter} | {shift} | {:.3} | {:.3} | {:.3} | {:.3} | {:+.1} | {:+.1} | {:+.1} |",
                g[0],
                g[1],
                g[2],
                g[3],
                pct(g[1]),
                pct(g[2]),
                pct(g[3])
            );
        }
    }

    println!();
    println!(
        "## Tracking: the adaptive design against the frozen one, lung C 50 R 5 -> C 10 R 50 at \
         breath 10 -> back at 30, {} seeds (mean per breath; worst breath in brackets)",
        args.seeds
    );
    println!();
    println!("| controller | phase | RMS slm | |volume error| % (worst) |");
    println!("|---|---|---|---|");
    for (name, mode, dither, max_iter) in [
        ("frozen", Mode::Frozen, None, 200),
        ("adaptive", Mode::Adapt, None, 200),
        ("adaptive + dither", Mode::Adapt, Some(DITHER), 200),
        (
            "restarts only (the running model's design)",
            Mode::Restart,
            None,
            200,
        ),
        ("adaptive, 5000 iterates", Mode::Adapt, None, 5000),
        (
            "adaptive + dither, 5000 iterates",
            Mode::Adapt,
            Some(DITHER),
            5000,
        ),
    ] {
        let all = runs(&at_iterates(&base, mode, dither, max_iter), args.seeds);
        for (label, from, to) in PHASES {
            let b: Vec<_> = all.iter().flat_map(|r| breaths_in(r, from, to)).collect();
            let rms: Vec<f64> = b.iter().map(|b| b.rms).collect();
            let vol: Vec<f64> = b.iter().map(|b| b.volume_error_pct().abs()).collect();
            let worst = vol.iter().copied().fold(0.0, f64::max);
            println!(
                "| {name} | {label} | {:.2} | {:.1} ({worst:.1}) |",
                mean_sd(&rms).0,
                mean_sd(&vol).0
            );
        }
        let swaps: usize = all
            .iter()
            .map(|r| {
                r.estimates
                    .iter()
                    .filter(|e| e.swapped_at.is_some())
                    .count()
            })
            .sum();
        let refused: usize = all
            .iter()
            .map(|r| {
                r.estimates
                    .iter()
                    .filter(|e| matches!(e.verdict, Some(Err(_))))
                    .count()
            })
            .sum();
        if mode != Mode::Frozen {
            println!("| {name} | swaps / refused re-estimates | {swaps} / {refused} | |");
        }
    }
}
