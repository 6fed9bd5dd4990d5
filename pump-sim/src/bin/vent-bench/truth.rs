//! The truth the re-estimates are held against: row 1's breath on a lung `(C, R)` as the
//! power-up's model sees it, through its static map.

use pump_sim::reid;
use pump_sim::vent_bench::power_up_plant;
use pump_sim::vent_bench::row1_lung;
use ridge_core::input_map::MapTable;

/// The flow of the truth's linearisation: row 1's square inspiration, 500 mL in 1 s above the
/// 5 slm bias, slm.
pub const INSPIRATION_FLOW: f64 = 35.0;

/// The truth of row 1's breath on one lung through a power-up's map.
pub struct Truth {
    /// The valve-open linearisation's gain at [`INSPIRATION_FLOW`], slm per slm of the map.
    pub gain: f64,
    /// Its 63 % rise, ticks (0 if it never rises so far).
    pub rise: usize,
    /// The closed-valve step from the 5 slm bias flow, the duty of [`INSPIRATION_FLOW`] held,
    /// 100 ticks, slm per slm of the map.
    pub closed: Vec<f64>,
}

impl Truth {
    /// The closed-valve step after `ticks` ticks (from 1); NaN past its end.
    pub fn closed_after(&self, ticks: usize) -> f64 {
        ticks
            .checked_sub(1)
            .and_then(|k| self.closed.get(k))
            .copied()
            .unwrap_or(f64::NAN)
    }
}

/// The truth of row 1's breath on the lung `(C, R)` as the model sees it through `table`: the
/// valve-open linearisation at [`INSPIRATION_FLOW`] and the closed-valve response.
pub fn truth_of(table: &MapTable, (c, r): (f64, f64)) -> Truth {
    let l = row1_lung(c, r);
    let plant = power_up_plant(&l);
    let open = reid::through_map(&reid::linearisation(&plant, &l, INSPIRATION_FLOW), table);
    let closed = reid::through_map(
        &reid::closed_valve_step(&plant, &l, 5.0, INSPIRATION_FLOW, 100),
        table,
    );
    Truth {
        gain: open.gain,
        rise: reid::rise63(&open.step).unwrap_or(0),
        closed: closed.step,
    }
}
