//! The firmware's flow controller with its three time constants (regulation `τ`, observer,
//! reference model) chosen per plant in hindsight, on the simulator itself: how close the
//! design method comes to the step-IAE target when its knobs are tuned with the plant known
//! (see `pump_sim::baseline::knobs`).
//!
//! ```text
//! cargo run --release -p pump-sim --bin control-knobs -- --all
//! cargo run --release -p pump-sim --bin control-knobs -- --plant sluggish --lung stiff --seeds 5
//! ```
//!
//! The computations live in `pump_sim::baseline`; this binary only parses flags and prints.

use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use pump_sim::baseline::experiment::{identify, run_identified, tune_zn};
use pump_sim::baseline::knobs::{grid, score_knobs, KnobScore, Knobs};
use pump_sim::baseline::table::{
    breath_pct, lung_label, summarise, Cases, BREATH_TARGET_PCT, IAE_RATIO_TARGET,
    OVERSHOOT_TARGET_PCT,
};
use pump_sim::baseline::Controller;
use pump_sim::PlantArgs;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;

/// Prints, per plant, the firmware's design and the best knobs of the grid, then the best
/// knobs shared by every plant (markdown).
#[derive(Debug, Parser)]
#[command(name = "control-knobs")]
struct Args {
    /// Which plants and seeds.
    #[command(flatten)]
    cases: Cases,
}

/// One plant: the ZN PID's mean step IAE and every set of knobs the design accepted.
struct PlantRun {
    plant: PlantArgs,
    zn_iae: f64,
    scores: Vec<KnobScore>,
}

impl PlantRun {
    fn name(&self) -> String {
        format!("{} | {}", self.plant.plant.name(), lung_label(&self.plant))
    }

    /// The targets other than the IAE: overshoot (noise-free) and, with a lung, breath RMS.
    fn admissible(&self, s: &KnobScore) -> bool {
        s.overshoot_pct <= OVERSHOOT_TARGET_PCT
            && (!self.plant.has_lung() || breath_pct(s.breath_rms) <= BREATH_TARGET_PCT)
    }

    fn ratio(&self, s: &KnobScore) -> f64 {
        s.iae / self.zn_iae
    }

    fn find(&self, k: &Knobs) -> Option<&KnobScore> {
        self.scores.iter().find(|s| s.knobs == *k)
    }
}

fn knobs_label(k: &Knobs) -> String {
    let r = k
        .reference_s()
        .map_or("none".to_owned(), |s| format!("{s:.2} s"));
    format!("×{} / ×{} / {r}", k.tau_x, k.observer_x)
}

fn run(plant: &PlantArgs, seeds: &[u64], grid: &[Knobs]) -> Result<PlantRun, String> {
    let zn = tune_zn(plant).map_err(|e| e.to_string())?;
    // One identification per seed: the knobs and the comparison's ZN PID run from it.
    let mut cases = Vec::new();
    let mut runs = Vec::new();
    for &seed in seeds {
        let identified = identify(plant, seed).map_err(|e| e.to_string())?;
        cases.push((identified.0.clone(), identified.2.clone(), seed));
        runs.push(run_identified(plant, seed, &zn, identified).map_err(|e| e.to_string())?);
    }
    let zn_iae = summarise(&runs, Controller::ZnPid)
        .ok_or("a ZN PID trace cannot be scored")?
        .iae;
    let c = &DEFAULT_CONFIG.control;
    let scores = grid
        .iter()
        .filter_map(|&k| score_knobs(&cases, c, k))
        .collect();
    Ok(PlantRun {
        plant: plant.clone(),
        zn_iae,
        scores,
    })
}

fn row(p: &PlantRun, s: &KnobScore) -> String {
    format!(
        "{} | {:.3} | {:.2} | {:.1} | {:.1} | {}",
        knobs_label(&s.knobs),
        s.iae,
        p.ratio(s),
        s.overshoot_pct,
        s.overshoot_noisy_pct,
        if p.plant.has_lung() {
            format!("{:.1}", breath_pct(s.breath_rms))
        } else {
            format!("({:.1})", breath_pct(s.breath_rms))
        }
    )
}

fn main() -> ExitCode {
    let args = Args::parse();
    let start = Instant::now();
    let grid = grid();
    let seeds = args.cases.seeds();
    let mut runs = Vec::new();
    for p in &args.cases.plants() {
        match run(p, &seeds, &grid) {
            Ok(r) => runs.push(r),
            Err(e) => {
                eprintln!("control-knobs: {}: {e}", p.describe());
                return ExitCode::FAILURE;
            }
        }
    }
    let command: Vec<String> = std::env::args().skip(1).collect();
    println!(
        "`cargo run --release -p pump-sim --bin control-knobs -- {}`: {} sets of knobs \
         (regulation τ × / observer τ_o × / reference model), seeds 1–{}. IAE: mean per step \
         with sensor noise, true flow; ZN: the ZN PID's on the same runs. Admissible: \
         noise-free overshoot ≤ {OVERSHOOT_TARGET_PCT} % and, with a lung, breath RMS ≤ \
         {BREATH_TARGET_PCT} % of peak (in brackets without a lung, not required).\n",
        command.join(" "),
        grid.len(),
        seeds.len()
    );
    println!(
        "| plant | lung | ZN PID IAE | knobs | IAE | IAE / ZN | overshoot (%) | noisy overshoot (%) | \
         breath (% peak) |"
    );
    println!("|---|---|---:|---|---:|---:|---:|---:|---:|");
    for p in &runs {
        let firmware = p.find(&Knobs::FIRMWARE);
        let best = p
            .scores
            .iter()
            .filter(|s| p.admissible(s))
            .min_by(|a, b| a.iae.total_cmp(&b.iae));
        for (what, s) in [("firmware", firmware), ("best", best)] {
            match s {
                Some(s) => println!("| {} | {:.3} | {what}: {} |", p.name(), p.zn_iae, row(p, s)),
                None => println!(
                    "| {} | {:.3} | {what}: none | | | | | |",
                    p.name(),
                    p.zn_iae
                ),
            }
        }
    }
    // Knobs shared by every plant: admissible everywhere, most plants within the IAE target,
    // then the smallest worst ratio.
    let mut shared: Vec<(usize, f64, f64, Knobs, Vec<f64>)> = grid
        .iter()
        .filter_map(|k| {
            let mut ratios = Vec::new();
            for p in &runs {
                let s = p.find(k).filter(|s| p.admissible(s))?;
                ratios.push(p.ratio(s));
            }
            let met = ratios.iter().filter(|&&r| r <= IAE_RATIO_TARGET).count();
            let worst = ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
            Some((met, worst, mean, *k, ratios))
        })
        .collect();
    shared.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.total_cmp(&b.1)));
    println!(
        "\nKnobs shared by all {} plants, admissible on each ({} sets; the 8 best, most \
         plants within IAE / ZN ≤ {IAE_RATIO_TARGET} first, then the smallest worst ratio):\n",
        runs.len(),
        shared.len()
    );
    println!("| knobs | within target | worst IAE / ZN | mean | per plant (table order) |");
    println!("|---|---:|---:|---:|---|");
    let top = shared.len().min(8);
    let firmware = shared.iter().skip(top).find(|s| s.3 == Knobs::FIRMWARE);
    for (m, w, mean, k, r) in shared.iter().take(top).chain(firmware) {
        let per: Vec<String> = r.iter().map(|x| format!("{x:.2}")).collect();
        let tag = if *k == Knobs::FIRMWARE {
            " (firmware)"
        } else {
            ""
        };
        println!(
            "| {}{tag} | {m} | {w:.2} | {mean:.2} | {} |",
            knobs_label(k),
            per.join(" ")
        );
    }
    eprintln!(
        "control-knobs: {} plant(s) × {} seed(s) × {} sets in {:.1} s",
        runs.len(),
        seeds.len(),
        grid.len(),
        start.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}
