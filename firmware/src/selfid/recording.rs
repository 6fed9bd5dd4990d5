//! The estimation record's statistics (exact integers, deviations from the operating point)
//! and the conversion of the model identified on them to absolute units.

use ridge_core::{ArxModel, InputMap, IntGram, Offset, Real};

use crate::units::{MODEL_SCALE, SLM_PER_COUNT};

/// Statistics of one estimation record.
#[derive(Debug, Clone)]
pub(super) struct Recording {
    /// The static map the record's inputs go through.
    pub(super) map: InputMap,
    /// Operating point: the map's flow at the base duty and the mean settled flow (counts).
    pub(super) v0: i16,
    pub(super) y0: i16,
    /// Exact statistics of the deviations `(v − v0, y − y0)`, `v` the map's flow at the
    /// applied duty.
    pub(super) gram: IntGram,
    /// `Σ y` and `Σ y²` of the flow counts, for the excitation check.
    pub(super) sum_y: i64,
    pub(super) sum_y2: i64,
    pub(super) gaps: u16,
}

impl Recording {
    pub(super) fn new(map: InputMap, v0: i16, y0: i16) -> Self {
        Recording {
            map,
            v0,
            y0,
            gram: IntGram::new(),
            sum_y: 0,
            sum_y2: 0,
            gaps: 0,
        }
    }

    /// RMS deviation of the flow from its mean, slm (exact integer variance first).
    ///
    /// Exact in `i64` for records of up to 65 535 samples (`n Σy² − (Σy)²` stays below 2⁶³
    /// with |y| ≤ 32 768); longer ones fall back to `f32` sums (128-bit integers would pull
    /// 1.7 KB of conversion code into the ATmega2560 image for a threshold check).
    pub(super) fn response_rms(&self) -> f32 {
        let n = self.gram.len();
        if n == 0 {
            return 0.0;
        }
        let var = match u16::try_from(n) {
            Ok(_) => {
                let n = i64::from(n);
                let var_n2 = n * self.sum_y2 - self.sum_y * self.sum_y;
                var_n2.max(0) as f32 / (n * n) as f32
            }
            Err(_) => {
                let nf = n as f32;
                let mean = self.sum_y as f32 / nf;
                let var = self.sum_y2 as f32 / nf - mean * mean;
                // Not f32::max: 140 bytes of libm on the ATmega2560 for one clamp.
                if var > 0.0 {
                    var
                } else {
                    0.0
                }
            }
        };
        ridge_core::Real::sqrt(var) * SLM_PER_COUNT
    }
}

/// Settle ticks (at the end of the settle phase) whose mean flow is the operating point.
pub const SETTLE_MEAN_TICKS: u16 = 50;

/// Converts a model identified on deviations from the operating point `(v0, y0)` (the map's
/// flow and the measured flow, counts) into the absolute model with an intercept (slm):
/// `c = c_dev + y0 (1 − Σθ) − v0 Σφ` (`v0`, `y0` in slm). Generic so that host tools check the
/// device's `f32` result with the same conversion in `f64`.
///
/// Errors: [`ridge_core::Error::NonFinite`] for non-finite coefficients.
pub fn absolute_model<T: Real>(
    dev: &ArxModel<T>,
    v0: i16,
    y0: i16,
) -> Result<ArxModel<T>, ridge_core::Error> {
    let mut sum_theta = T::ZERO;
    for t in dev.theta() {
        sum_theta += *t;
    }
    let mut sum_phi = T::ZERO;
    for f in dev.phi() {
        sum_phi += *f;
    }
    let slm = T::from_f64(MODEL_SCALE.y);
    let c = dev.intercept() + T::from_i64(i64::from(y0)) * slm * (T::ONE - sum_theta)
        - T::from_i64(i64::from(v0)) * slm * sum_phi;
    ArxModel::new(
        dev.theta(),
        dev.phi(),
        dev.structure().d,
        Offset::Intercept,
        c,
    )
}
