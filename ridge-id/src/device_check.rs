//! `--device`: what the pump does when it identifies itself, as `ridge-id` options, taken
//! from the firmware's own settings (`ridge_pump_firmware::selfid::DEFAULT_CONFIG`, the
//! configuration the board images run with).
//!
//! The pump (`firmware/src/selfid/`): the estimation record's samples `(v − v0, y − y0)`,
//! `v` the map of the attempt's `MAP` line at the duty, around the operating point of its
//! `EXCITE` line go into exact integer statistics with zero history before the record; the
//! structure search is ridge-core's `Search` of the settings (Ridge-M γ = 1000, β = 0.01,
//! ε = 1e-6, 200 iterates, delay-free AIC with α = 12, p 1..=5, q 1..=6, d 0..=6, an
//! intercept, exact pruning) in `f32`; the model of the deviations becomes the absolute model
//! with the intercept `c = c_dev + y0 (1 − Σθ) − v0 Σφ`. `--device` sets exactly these options
//! (the hyper-parameters are the firmware's `f32` constants as the decimals its source names;
//! `--phase` takes the segment's input through the capture's `MAP` line, `src/phase/`); the
//! arithmetic stays `ridge-id`'s `f64`, so coefficients agree to `f32` precision, not bit for
//! bit. The validation record does not change the model (it only accepts or rejects it), so
//! `--device` sets nothing for it.

use ridge_core_host::{Criterion, Grid, MethodKind, Offset, OrderRange};
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;

use crate::error::IdError;
use crate::initial::Initial;
use crate::options::{GammaScale, Options, Refine, Select};
use crate::phase::{SegmentOptions, EXCITE_PHASE};

/// The command-line options `--device` stands for, as they would be typed (for messages and
/// the docs; `device_options_are_the_documented_ones` checks the two agree).
pub const DEVICE_OPTIONS: &str = "--phase excite --operating-point log --initial zero \
--offset intercept --method ridge-m --criterion aic --gamma 1000 --beta 0.01 --alpha 12 \
--max-iter 200 --tol 1e-6 --p 1..=5 --q 1..=6 --d 0..=6";

/// Sets `opts` to the firmware's identification: the search settings of
/// `DEFAULT_CONFIG.search`, zero initial conditions, no offset, and (unless a phase is
/// already chosen) the last complete `excite` segment around the operating point of its
/// `# EXCITE` line.
///
/// Errors: a firmware setting `ridge-id` cannot express (an estimator other than Ridge-M or a
/// name unknown to ridge-core-host) — not the case for the firmware's defaults.
pub fn apply(opts: &mut Options) -> Result<(), IdError> {
    let s = &DEFAULT_CONFIG.search;
    let unsupported = |what: &str| {
        IdError::Usage(format!(
            "--device: the firmware's search uses {what}, which ridge-id cannot reproduce"
        ))
    };
    let ridge_m = match s.method {
        ridge_core::Method::RidgeM(r) => r,
        other => return Err(unsupported(other.kind().name())),
    };
    opts.method = MethodKind::RidgeM;
    opts.criterion = s
        .criterion
        .name()
        .parse::<Criterion>()
        .map_err(|_| unsupported(s.criterion.name()))?;
    opts.offset = s
        .offset
        .name()
        .parse::<Offset>()
        .map_err(|_| unsupported(s.offset.name()))?;
    // The device's γ is in its data's units (duty fraction, slm), as printed.
    opts.hyper.gamma = decimal(ridge_m.gamma);
    opts.hyper.gamma_scale = GammaScale::Data;
    opts.hyper.beta = decimal(ridge_m.beta);
    opts.hyper.tol = decimal(ridge_m.tol);
    opts.hyper.max_iter = ridge_m.max_iter;
    opts.hyper.alpha = decimal(s.alpha);
    // The pump's statistics assume zero history before the record (around the operating
    // point, where that is what the plant had).
    opts.hyper.initial = Initial::Zero;
    let range = |r: ridge_core::OrderRange| OrderRange::new(r.min, r.max);
    opts.grid = Grid {
        p: range(s.grid.p),
        q: range(s.grid.q),
        d: range(s.grid.d),
    };
    opts.structure = None;
    // The pump's model is the search's, by its criterion, as it is.
    opts.select = Select::Criterion;
    opts.refine = Refine::None;
    if opts.segment.is_none() {
        opts.segment = Some(SegmentOptions::excite());
    }
    debug_assert_eq!(
        EXCITE_PHASE,
        ridge_pump_firmware::selfid::State::Excite.name()
    );
    Ok(())
}

/// The `f64` of the shortest decimal that reads back as `v` (`0.01f32` → `0.01`, where
/// widening gives 0.0099999998): the value the firmware's source names. The two differ by
/// less than an `f32` rounding, far below what the `f32` solve changes.
fn decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::from(v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Cli, Command};
    use clap::Parser;

    fn parsed(extra: &str) -> Options {
        let mut argv = vec!["ridge-id", "identify", "--input", "x.csv"];
        argv.extend(extra.split_whitespace());
        match Cli::try_parse_from(argv).unwrap().command {
            Command::Identify(a) => a.options().unwrap(),
            _ => panic!("not an identify command"),
        }
    }

    #[test]
    fn device_options_are_the_documented_ones() {
        let device = parsed("--device");
        let spelled = parsed(DEVICE_OPTIONS);
        // The documented spelling gives exactly the firmware's values.
        assert_eq!(device, spelled);
        // A phase of one's own is kept.
        let other = parsed("--device --phase validate --attempt 2");
        let seg = other.segment.unwrap();
        assert_eq!((seg.phase.as_str(), seg.attempt), ("validate", Some(2)));
    }
}
