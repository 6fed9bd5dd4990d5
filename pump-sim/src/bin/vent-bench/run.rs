//! What the tables share: the power-ups and cells they run (failures printed and skipped) and
//! the adaptive controller's knobs under study.

use pump_sim::vent_bench::{
    power_up, row1_lung, run_cell, zn_for, Cell, CellRun, Outcomes, Policy, PowerUp,
};
use pump_sim::LungParams;

/// The adaptive controller's knobs under study in the lung-change tables (`--trim`,
/// `--swap-when` and the policy's other flags).
#[derive(Clone, Copy, Debug)]
pub struct Knobs {
    /// The per-breath volume trim on.
    pub trim: bool,
    /// When and how the adaptive controller swaps an accepted re-estimate in.
    pub policy: Policy,
}

impl Knobs {
    /// `cell` with these knobs.
    pub fn apply(&self, cell: Cell) -> Cell {
        Cell {
            trim: self.trim,
            policy: self.policy,
            ..cell
        }
    }
}

/// The power-ups of `lung` for `seeds`, with their ZN tuning; failures printed and skipped.
pub fn power_ups(lung: &LungParams, seeds: u64) -> Vec<PowerUp> {
    let zn = match zn_for(lung) {
        Ok(z) => z,
        Err(e) => {
            eprintln!(
                "ZN tuning, C {} R {}: {e}",
                lung.compliance, lung.resistance
            );
            return Vec::new();
        }
    };
    (1..=seeds)
        .filter_map(|seed| match power_up(lung, seed, &zn) {
            Ok(p) => Some(p),
            Err(e) => {
                eprintln!(
                    "power-up C {} R {} seed {seed}: {e}",
                    lung.compliance, lung.resistance
                );
                None
            }
        })
        .collect()
}

/// The power-ups (seeds 1 to `seeds`) into row 1's lung with `(C, R)`, its PEEP valve at 0:
/// a lung change's first lung.
pub fn power_ups_on((c, r): (f64, f64), seeds: u64) -> Vec<PowerUp> {
    power_ups(
        &LungParams {
            peep: 0.0,
            ..row1_lung(c, r)
        },
        seeds,
    )
}

/// `cell` from every power-up; failures printed and skipped.
pub fn runs(ups: &[PowerUp], cell: &Cell) -> Vec<CellRun> {
    ups.iter()
        .filter_map(|p| match run_cell(p, cell) {
            Ok(r) => Some(r),
            Err(e) => {
                eprintln!(
                    "row {} {:?} {} seed {}: {e}",
                    cell.row.row,
                    cell.wave,
                    cell.ctrl.name(),
                    p.seed
                );
                None
            }
        })
        .collect()
}

/// The largest of `v`; −∞ if empty.
pub fn max(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(f64::NEG_INFINITY, f64::max)
}

/// The refusals of `o` as a table cell: `fit, model, other, design`.
pub fn refused(o: &Outcomes) -> String {
    format!("{}, {}, {}, {}", o.fit, o.model, o.other, o.design_refused)
}
