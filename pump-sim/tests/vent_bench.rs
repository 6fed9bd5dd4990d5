//! The ventilation benchmark (`pump_sim::vent_bench`) against the simulated truth: the
//! firmware's power-up, `VENT` program, trim and valve on the host, scored on what the lung
//! itself gained while its valve was closed. The full table is `vent-bench`'s job; these are
//! the properties docs/ventilation.md states, on a few cells.

use pump_sim::iso::iso_row;
use pump_sim::reid::{self, Study};
use pump_sim::vent_bench::{
    change_verdict, power_up, pressure_limited, row_lung, run_cell, score, zn_for, Cell, CellRun,
    ChangeAt, Ctrl, LungChange, Policy, PowerUp, SwapWhen,
};
use pump_sim::LungParams;
use ridge_pump_firmware::setpoint::Shape;

fn ups(row: u8, seeds: &[u64]) -> Vec<PowerUp> {
    let r = iso_row(row).expect("row");
    let lung = row_lung(&r, 0.0);
    let zn = zn_for(&lung).expect("ZN tuning");
    seeds
        .iter()
        .map(|&s| power_up(&lung, s, &zn).expect("power-up"))
        .collect()
}

fn cell(row: u8, ctrl: Ctrl) -> Cell {
    Cell::new(iso_row(row).expect("row"), Shape::Square, ctrl)
}

/// Every controller holds rows 1, 4 and 7 (square, trim on, sensor noise on) within the
/// standards' ±(4 mL + 15 %) from breath 3 on the lung's own delivered volume, with the PEEP
/// within ±2 cmH₂O; the firmware's own delivered volume (its readings integrated) is within
/// 2 mL + 2 % of the lung's.
#[test]
fn every_controller_holds_rows_1_4_7_in_the_standards_band() {
    for row in [1, 4, 7] {
        let ups = ups(row, &[1, 2]);
        for ctrl in Ctrl::ALL {
            for p in &ups {
                let run = run_cell(p, &cell(row, ctrl)).expect("run");
                assert_eq!(run.breaths.len(), 12);
                let s = score(&run, 3);
                let what = format!("row {row} {} seed {}: {:?}", ctrl.name(), p.seed, s);
                assert!(s.pass15, "{what}");
                assert!(s.peep_err <= 2.0, "{what}");
                for b in &run.breaths {
                    let tol = 2.0 + 0.02 * b.delivered_ml;
                    assert!(
                        (b.measured_ml - b.delivered_ml).abs() <= tol,
                        "{what}: breath {} firmware {} lung {}",
                        b.number,
                        b.measured_ml,
                        b.delivered_ml
                    );
                }
            }
        }
    }
}

/// The frozen power-up design with the trim: every breath from 3 within the issue's ±(4 mL +
/// 5 %) on rows 1, 4 and 7 (square).
#[test]
fn the_frozen_design_with_the_trim_meets_the_five_percent_target() {
    for row in [1, 4, 7] {
        for p in &ups(row, &[1, 2]) {
            let run = run_cell(p, &cell(row, Ctrl::Frozen)).expect("run");
            assert!(score(&run, 3).pass5, "row {row} seed {}", p.seed);
        }
    }
}

/// The trim is what closes the volume: without it the frozen controller delivers short of the
/// set volume on every breath of row 7 (the flow controller alone loses volume against the
/// lung), with it breaths 3 on are within 5 %.
#[test]
fn without_the_trim_the_volume_is_short() {
    let p = &ups(7, &[1])[0];
    let off = run_cell(
        p,
        &Cell {
            trim: false,
            ..cell(7, Ctrl::Frozen)
        },
    )
    .expect("run");
    assert!(off.breaths.iter().all(|b| b.error_pct() < -5.0), "{off:?}");
}

fn after_change(p: &PowerUp, ctrl: Ctrl, at: ChangeAt, to: LungParams) -> CellRun {
    run_cell(
        p,
        &Cell {
            breaths: 10,
            changes: vec![LungChange {
                breath: 5,
                at,
                lung: to,
            }],
            ..cell(1, ctrl)
        },
    )
    .expect("run")
}

/// Row 1's lung becomes C 10 mL/cmH₂O at breath 5's boundary: the frozen controller and the
/// trim have the volume back within 15 % by breath 6, and the lung's own pressure then obeys
/// the physics the docs use: the peak airway pressure is at least PEEP + V/C of the volume
/// delivered, so it rises by far more than the +5 cmH₂O a breath the issue asks, which
/// `pressure_limited` shows would take 7 breaths to reach the 15 % band.
#[test]
fn a_stiffer_lung_cannot_have_both_the_volume_and_the_pressure_rule() {
    let p = &ups(1, &[1])[0];
    let stiff = LungParams {
        compliance: 10.0,
        ..row_lung(&iso_row(1).expect("row"), 5.0)
    };
    let run = after_change(p, Ctrl::Frozen, ChangeAt::Boundary, stiff);
    let b = |n: u32| run.breaths[n as usize - 1];
    assert!(b(6).within(0.15), "{:?}", b(6));
    for n in 5..=10 {
        let x = b(n);
        assert!(
            x.peak_pressure >= 5.0 + x.delivered_ml / 10.0,
            "breath {n}: {x:?}"
        );
    }
    assert!(b(6).peak_pressure - b(4).peak_pressure > 5.0 * 2.0);
    let limited = pressure_limited(500.0, 1.0, 5.0, (50.0, 5.0), (10.0, 5.0), 5.0);
    assert!(limited.within15 > 2);
}

/// The swap rule on the study's demo breaths (`reid::Study::lung_change`, adult lung): with
/// `swap_below_fit` 90 % no re-estimate replaces the power-up controller on the adult lung,
/// where without it some do (the power-up model's own held-out fit is above 90 % there).
#[test]
fn the_swap_rule_keeps_the_power_up_controller_on_the_adult_lung() {
    let swaps = |x: Option<f64>| -> usize {
        (1..=3)
            .map(|seed| {
                let run = reid::run(&Study {
                    breaths: 10,
                    changes: Vec::new(),
                    swap_below_fit: x,
                    ..Study::lung_change(seed)
                })
                .expect("run");
                run.estimates
                    .iter()
                    .filter(|e| e.swapped_at.is_some())
                    .count()
            })
            .sum()
    };
    assert!(swaps(None) > 0);
    assert_eq!(swaps(Some(90.0)), 0);
    assert_eq!(swaps(Some(100.0)), swaps(None));
}

/// Row 1's breath on `from` (power-up there, seed `seed`), the lung `to` from breath 6's
/// boundary, 14 breaths, under `policy` (adaptive) or the frozen design (`None`).
fn change_run(seed: u64, from: (f64, f64), to: (f64, f64), policy: Option<Policy>) -> CellRun {
    let row1 = iso_row(1).expect("row");
    let lung = |(c, r): (f64, f64)| LungParams {
        compliance: c,
        resistance: r,
        ..row_lung(&row1, row1.peep)
    };
    let first = LungParams {
        peep: 0.0,
        ..lung(from)
    };
    let p = power_up(&first, seed, &zn_for(&first).expect("ZN")).expect("power-up");
    let cell = Cell {
        breaths: 14,
        changes: vec![LungChange {
            breath: 6,
            at: ChangeAt::Boundary,
            lung: lung(to),
        }],
        policy: policy.unwrap_or(Policy::ALWAYS),
        ..Cell::new(
            pump_sim::iso::IsoRow {
                compliance: from.0,
                resistance: from.1,
                ..row1
            },
            Shape::Square,
            if policy.is_some() {
                Ctrl::Adaptive
            } else {
                Ctrl::Frozen
            },
        )
    };
    run_cell(&p, &cell).expect("run")
}

/// The recommended swap policy (docs/ventilation.md, *Why the re-designed controller loses
/// volume*): an accepted re-estimate is swapped in only while the volume alarm is raised.
/// After R 5 → 50 and after C 50 → 10 with R 5 → 50 (breath 6's boundary; seeds 1, 6 and 9)
/// every breath from the change's 2nd is within ±(4 mL + 15 %) and from its 4th within
/// ±(4 mL + 5 %), on the lung's own delivered volume; swapping always misses the 5 % band in
/// some of these runs (seed 9: a controller re-designed from the adult lung's volume breaths,
/// swapped in the breath after the change, delivers −23.7 %).
#[test]
fn swapping_only_on_the_volume_alarm_keeps_the_volume_after_a_lung_change() {
    let alarm = Policy {
        when: SwapWhen::VolumeAlarm,
        ..Policy::ALWAYS
    };
    let mut always_missed = 0;
    for to in [(50.0, 50.0), (10.0, 50.0)] {
        for seed in [1, 6, 9] {
            let run = change_run(seed, (50.0, 5.0), to, Some(alarm));
            let v = change_verdict(&run, 6);
            assert!(v.meets15() && v.meets5(), "{to:?} seed {seed}: {v:?}");
            let today = change_run(seed, (50.0, 5.0), to, Some(Policy::ALWAYS));
            always_missed += usize::from(!change_verdict(&today, 6).meets5());
        }
    }
    assert!(always_missed > 0);
}

/// Without a change the recommended policy is never worse than the frozen power-up design by
/// more than 1 % of the set volume on any breath from 3 (rows 1, 4 and 7, square, seeds 1-2).
#[test]
fn swapping_only_on_the_volume_alarm_costs_nothing_on_an_unchanged_lung() {
    let alarm = Policy {
        when: SwapWhen::VolumeAlarm,
        ..Policy::ALWAYS
    };
    for row in [1, 4, 7] {
        for p in &ups(row, &[1, 2]) {
            let frozen = run_cell(p, &cell(row, Ctrl::Frozen)).expect("run");
            let ours = run_cell(
                p,
                &Cell {
                    policy: alarm,
                    ..cell(row, Ctrl::Adaptive)
                },
            )
            .expect("run");
            for (a, f) in ours.breaths.iter().zip(&frozen.breaths).skip(2) {
                assert!(
                    a.error_pct().abs() <= f.error_pct().abs() + 1.0,
                    "row {row} seed {}: breath {} {a:?} frozen {f:?}",
                    p.seed,
                    a.number
                );
            }
        }
    }
}
