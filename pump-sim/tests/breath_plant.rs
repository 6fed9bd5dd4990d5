//! The ventilation benchmark with the breath-plant study's knobs (`vent_bench::BreathPlant`):
//! an adaptive loop that re-estimates each inspiration only, at a larger structure, and never
//! swaps is the frozen power-up loop breath for breath, and its estimates have the structure
//! asked for; the inspiration's tracking RMS is part of the breath's.

use pump_sim::iso::iso_row;
use pump_sim::reid::Feed;
use pump_sim::vent_bench::{
    power_up, row_lung, run_cell_figures, zn_for, BreathPlant, Cell, Ctrl, Policy, SwapWhen,
};
use ridge_pump_firmware::setpoint::Shape;

#[test]
fn an_inspiration_only_monitor_is_the_frozen_loop_and_re_estimates_the_larger_structure() {
    let row = iso_row(1).expect("row 1");
    let lung = row_lung(&row, 0.0);
    let p = power_up(&lung, 2, &zn_for(&lung).expect("ZN")).expect("power-up");
    let base = Cell {
        breaths: 8,
        ..Cell::new(row, Shape::Square, Ctrl::Frozen)
    };
    let monitor = Cell {
        ctrl: Ctrl::Adaptive,
        policy: Policy {
            when: SwapWhen::Never,
            ..Policy::ALWAYS
        },
        breath_plant: BreathPlant {
            feed: Feed {
                inspiration_only: true,
                extra_p: 1,
                extra_q: 1,
            },
            ..BreathPlant::TODAY
        },
        ..base.clone()
    };
    let (frozen, frozen_insp) = run_cell_figures(&p, &base).expect("frozen");
    let (run, insp) = run_cell_figures(&p, &monitor).expect("monitor");
    assert_eq!(frozen.breaths, run.breaths);
    assert_eq!(frozen_insp, insp);
    let s = p.switchover.model.structure();
    let models: Vec<_> = run
        .estimates
        .iter()
        .filter_map(|e| e.model.and_then(Result::ok))
        .collect();
    assert!(models.len() >= 3, "{} models", models.len());
    for m in models {
        let t = m.structure();
        assert_eq!((t.p, t.q, t.d), (s.p + 1, s.q + 1, s.d));
    }
    // Row 1: 20 /min (300 ticks), Ti 1 s (100 ticks): the inspiration's squared errors are a
    // part of the breath's, and the square's rise makes them non-zero.
    assert_eq!(insp.len(), run.breaths.len());
    for (b, i) in run.breaths.iter().zip(&insp) {
        assert!(*i > 0.0 && i * i * 100.0 <= b.rms * b.rms * 300.0 * (1.0 + 1e-9));
    }
}

/// A ±1 slm setpoint dither (`BreathPlant::dither`) reaches the loop: the frozen loop's flow
/// moves with it (the inspiration's RMS against the undithered program changes, by less than
/// the dither's own 1 slm RMS plus a half), and every breath from the 3rd stays within
/// ±(4 mL + 5 %) with the trim.
#[test]
fn a_setpoint_dither_moves_the_flow_by_about_its_size() {
    let row = iso_row(1).expect("row 1");
    let lung = row_lung(&row, 0.0);
    let p = power_up(&lung, 1, &zn_for(&lung).expect("ZN")).expect("power-up");
    let base = Cell {
        breaths: 8,
        ..Cell::new(row, Shape::Square, Ctrl::Frozen)
    };
    let dithered = Cell {
        breath_plant: BreathPlant {
            dither: Some(pump_sim::reid::Dither {
                amplitude: 1.0,
                hold: 4,
            }),
            ..BreathPlant::TODAY
        },
        ..base.clone()
    };
    let (_, plain) = run_cell_figures(&p, &base).expect("plain");
    let (run, insp) = run_cell_figures(&p, &dithered).expect("dithered");
    let mean = |v: &[f64]| v.iter().skip(2).sum::<f64>() / (v.len() - 2) as f64;
    let (a, b) = (mean(&plain), mean(&insp));
    assert!(a != b && (b - a).abs() < 1.5, "{a} → {b}");
    assert!(run.breaths.iter().skip(2).all(|b| b.within(0.05)));
}
