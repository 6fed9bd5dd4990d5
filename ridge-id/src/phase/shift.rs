//! The operating point of `--phase`: the statistics of the deviations from it
//! ([`read_shifted`]) and the absolute model of a model of those deviations
//! ([`absolute_model`]).

use ridge_core_host::{ArxModel, MeasuredGram, Offset};

use crate::csv::Sample;
use crate::error::IdError;
use crate::eval::{read_samples, RecordStats};
use crate::input::{read_input, Input};

/// The statistics of `input` with the operating point `shift = (u0, y0)` subtracted from
/// every sample (none: [`read_input`]), into the empty `gram`; the reported ranges are those
/// of the absolute samples.
///
/// Errors: as [`read_input`].
pub fn read_shifted(
    input: &Input,
    gram: MeasuredGram<f64>,
    shift: Option<(f64, f64)>,
) -> Result<RecordStats, IdError> {
    let Some((u0, y0)) = shift else {
        return read_input(input, gram);
    };
    let mut stats = read_samples(
        input.name(),
        input.samples()?.map(|s| {
            s.map(|s| Sample {
                u: s.u - u0,
                y: s.y - y0,
                ..s
            })
        }),
        gram,
    )?;
    stats.u_range = (stats.u_range.0 + u0, stats.u_range.1 + u0);
    stats.y_range = (stats.y_range.0 + y0, stats.y_range.1 + y0);
    Ok(stats)
}

/// The absolute model of a model `dev` identified on the deviations from the operating point
/// `(u0, y0)`: the same θ, φ and delay, with the intercept
/// `c = c_dev + y0 (1 − Σθ) − u0 Σφ` (the firmware's `selfid::absolute_model`, in `f64`).
///
/// Errors: [`ridge_core_host::Error::NonFinite`] for non-finite coefficients.
pub fn absolute_model(
    dev: &ArxModel<f64>,
    (u0, y0): (f64, f64),
) -> Result<ArxModel<f64>, ridge_core_host::Error> {
    let sum_theta: f64 = dev.theta().iter().sum();
    let sum_phi: f64 = dev.phi().iter().sum();
    let c = dev.intercept() + y0 * (1.0 - sum_theta) - u0 * sum_phi;
    ArxModel::new(
        dev.theta(),
        dev.phi(),
        dev.structure().d,
        Offset::Intercept,
        c,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ridge_core_host::Offset;

    #[test]
    fn absolute_model_moves_the_operating_point_into_the_intercept() {
        let dev = ArxModel::new(&[0.5, 0.2], &[10.0], 1, Offset::None, 0.0).unwrap();
        let abs = absolute_model(&dev, (0.3, 20.0)).unwrap();
        assert_eq!(abs.offset(), Offset::Intercept);
        // At the operating point the absolute model is in equilibrium.
        let y = 0.5 * 20.0 + 0.2 * 20.0 + 10.0 * 0.3 + abs.intercept();
        assert!((y - 20.0).abs() < 1e-12, "{y}");
    }
}
