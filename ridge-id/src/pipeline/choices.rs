//! What a run chose for the user, and why ([`choices`] → the report's [`Choice`]s): the
//! scale-free `γ`, the intercept, and what `--select auto` and `--refine auto` became.

use super::read::Records;
use super::tune::Tuned;
use crate::numfmt::{num, typed};
use crate::options::{Options, Refine, Select};
use crate::outcome::Choice;
use ridge_core_host::Offset;

/// The choices of a run with `opts` on `rec`, tuned into `tuned`.
pub(super) fn choices(opts: &Options, rec: &Records, tuned: &Tuned) -> Vec<Choice> {
    let mut out = Vec::new();
    if rec.standard.is_some() {
        out.push(Choice {
            setting: "gamma",
            value: format!("{} on the standardised record", typed(opts.hyper.gamma)),
            why: format!(
                "no --gamma: the estimator ran on u / {} and y / {} (the estimation record's \
                 standard deviations), the coefficients are in the data's units: the model does \
                 not depend on the units (an explicit --gamma is in the data's units, eq. 12)",
                num(rec.est.u_std),
                num(rec.est.y_std)
            ),
        });
    }
    if opts.offset == Offset::Intercept {
        out.push(Choice {
            setting: "offset",
            value: "intercept".into(),
            why: "estimated, never shrunk: it models an offset of the log (a sensor's zero, a \
                  dead zone, an output level) and is about 0 without one (--offset none: the \
                  paper's model)"
                .into(),
        });
    }
    if let (Select::FreeRun, Some(why)) = tuned.select {
        out.push(Choice {
            setting: "select",
            value: Select::FreeRun.name().into(),
            why: why.into(),
        });
    }
    if let (Refine::Oe, Some(why)) = tuned.refine {
        out.push(Choice {
            setting: "refine",
            value: Refine::Oe.name().into(),
            why: why.into(),
        });
    }
    out
}
