//! The pipeline's last step: the PNGs of `--plot` ([`render`] → [`Plots`]): the fit, the
//! residual analysis, and the simulated closed-loop step of `--control`.

use std::path::{Path, PathBuf};

use ridge_core_host::ArxModel;

use super::controller::Controlled;
use super::read::Records;
use super::score::Scored;
use crate::error::IdError;
use crate::eval::Figures;
use crate::options::Options;
use crate::plot::{self, control_plot_path, residuals_plot_path, Axes, Panel};

/// The PNGs written besides `--plot OUT.png` itself.
#[derive(Debug, Default)]
pub(super) struct Plots {
    /// `OUT-control.png`, when a controller was designed and its step simulated.
    pub control: Option<PathBuf>,
    /// `OUT-residuals.png`, when a record had residuals to analyse.
    pub residuals: Option<PathBuf>,
}

/// The file name of `p`, for plot titles.
fn path_name(p: &Path) -> String {
    p.file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Writes the plots of `--plot` (nothing without it): the closed-loop step of `--control`,
/// the fit of `model` on each record, the residual analysis.
///
/// Errors: a PNG that cannot be written.
pub(super) fn render(
    opts: &Options,
    rec: &Records,
    model: &ArxModel<f64>,
    scored: &Scored,
    ctl: &Controlled,
) -> Result<Plots, IdError> {
    let mut plots = Plots::default();
    let Some(path) = &opts.plot else {
        return Ok(plots);
    };
    let s = model.structure();
    // A capture's units are the pump's; a plain CSV's are unknown: its columns are named.
    let axes = match opts.segment {
        Some(_) => Axes::pump(),
        None => Axes::columns(),
    };
    if let (Some(step), Some(designed)) =
        (&ctl.step, ctl.report.as_ref().and_then(|r| r.designed()))
    {
        let d = &designed.design;
        let title = format!(
            "closed-loop setpoint steps (simulated on the model): {}   ({},{},{})   \
             pole placement, tau {} s, margin {:.2}",
            path_name(rec.est_in.name()),
            s.p,
            s.q,
            s.d,
            (d.tau * 1e4).round() / 1e4,
            d.modulus_margin
        );
        let out = control_plot_path(path);
        plot::write_control_png(&out, &axes, &title, step)?;
        plots.control = Some(out);
    }
    let Some(et) = &scored.est_trace else {
        return Ok(plots);
    };
    let title = |what: &str, p: &Path, f: &Figures| {
        format!(
            "{what}: {}   {} ({},{},{})   free-run fit {:.1} %, RMSE {:.4}",
            path_name(p),
            opts.method.name(),
            s.p,
            s.q,
            s.d,
            f.fit_free_run,
            f.rmse_free_run
        )
    };
    let mut panels = vec![Panel {
        title: title("estimation", rec.est_in.name(), &scored.estimation),
        trace: et,
    }];
    if let (Some(vt), Some(vi), Some(vf)) = (&scored.val_trace, &rec.val_in, &scored.validation) {
        panels.push(Panel {
            title: title("validation", vi.name(), vf),
            trace: vt,
        });
    }
    plot::write_fit_png(path, &axes, &panels)?;
    let mut rows = Vec::new();
    for (what, f) in [
        ("estimation", Some(&scored.estimation)),
        ("validation", scored.validation.as_ref()),
    ] {
        if let Some(r) = f.and_then(|f| f.residuals.as_ref()) {
            rows.push((what.to_string(), r));
        }
    }
    if !rows.is_empty() {
        let out = residuals_plot_path(path);
        plot::write_residuals_png(&out, &rows)?;
        plots.residuals = Some(out);
    }
    Ok(plots)
}
