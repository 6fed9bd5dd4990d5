//! The text printer: a [`Report`] as the readable report ([`Report::to_text`]).

use std::fmt::Write as _;

use ridge_core_host::{Criterion, MethodKind, Offset};

use crate::eval::Figures;
use crate::initial::Initial;
use crate::numfmt::{list, num, typed as hp};
use crate::options::Select;
use crate::outcome::Report;

impl Report {
    /// The model as an equation, e.g. `y(t) = 1.2 y(t-1) - 0.4 y(t-2) + 0.5 u(t-3) + 0.1`.
    pub fn equation(&self) -> String {
        let m = &self.model;
        let d = usize::from(m.structure().d);
        let mut terms: Vec<(f64, String)> = Vec::new();
        for (i, &t) in m.theta().iter().enumerate() {
            terms.push((t, format!(" y(t-{})", i + 1)));
        }
        for (j, &f) in m.phi().iter().enumerate() {
            let lag = j + d;
            let u = if lag == 0 {
                " u(t)".to_string()
            } else {
                format!(" u(t-{lag})")
            };
            terms.push((f, u));
        }
        if m.offset() == Offset::Intercept {
            terms.push((m.intercept(), String::new()));
        }
        let mut out = String::from("y(t) =");
        for (k, (c, name)) in terms.iter().enumerate() {
            let sign = if *c < 0.0 { "-" } else { "+" };
            if k == 0 {
                let lead = if *c < 0.0 { " -" } else { "" };
                let _ = write!(out, "{lead} {}{name}", num(c.abs()));
            } else {
                let _ = write!(out, " {sign} {}{name}", num(c.abs()));
            }
        }
        out
    }

    /// The readable report.
    pub fn to_text(&self) -> String {
        let mut o = String::new();
        let m = &self.model;
        let s = m.structure();
        let h = &self.hyper;
        let _ = writeln!(
            o,
            "ridge-id: ARX model of {} ({} samples)",
            self.input.display(),
            self.input_rows
        );
        // γ on the standardised record says so; in the data's units it reads as typed.
        let gamma = match self.standardised {
            Some(_) => format!("{} on the standardised record", hp(h.gamma)),
            None => hp(h.gamma),
        };
        let method = match self.method {
            MethodKind::RidgeM => format!(
                "ridge-m (gamma {gamma}, beta {}, tol {}, max-iter {})",
                hp(h.beta),
                hp(h.tol),
                h.max_iter
            ),
            MethodKind::Ridge => format!("ridge (gamma {gamma})"),
            MethodKind::Ols => "ols (least squares)".to_string(),
            MethodKind::Rls => format!(
                "rls (lambda {}, delta {}); structure from a ridge-m search (gamma {gamma}, beta {}, tol {}, max-iter {})",
                hp(h.lambda),
                hp(h.delta),
                hp(h.beta),
                hp(h.tol),
                h.max_iter
            ),
            MethodKind::AdaptiveLasso => {
                "alasso (adaptive LASSO, weights 1/|w_ols|, lambda by BIC)".to_string()
            }
        };
        let _ = writeln!(o, "  method      {method}");
        let crit = match self.criterion {
            Criterion::Paper => {
                format!("paper: N ln(RSS/N) + alpha (p+q+d), alpha {}", hp(h.alpha))
            }
            Criterion::Aic => format!(
                "aic (delay-free): N ln(RSS/N) + alpha (p+q), alpha {}",
                hp(h.alpha)
            ),
            Criterion::Bic => "bic: N ln(RSS/N) + ln(N) (p+q)".to_string(),
            Criterion::Validation => {
                "validation: N_v ln(RSS_v/N_v), one-step residuals on the validation record"
                    .to_string()
            }
        };
        let _ = writeln!(o, "  criterion   {crit}");
        let initial = match self.hyper.initial {
            Initial::Measured => format!(
                "measured: the first M = {} samples fill the lag history, rows M+1..N",
                self.initial_samples
            ),
            Initial::Zero => "zero: zero history before the record, rows 1..N (eq. 6)".into(),
        };
        let _ = writeln!(o, "  initial     {initial}");
        if let Some(seg) = &self.segment {
            o.push_str(&seg.to_text(m));
        }
        let search = if self.search.fixed {
            "fixed by --structure".to_string()
        } else {
            format!(
                "{} candidates, {} fitted (the rest pruned exactly), {} not fittable",
                self.search.candidates, self.search.evaluated, self.search.skipped
            )
        };
        let _ = writeln!(o, "  search      {search}");
        // The choices made for the user: γ and the offset here, `auto` on the select and
        // refine lines.
        let auto = |setting: &str| {
            self.choices
                .iter()
                .find(|c| c.setting == setting)
                .map(|c| format!(" (auto: {})", c.why))
                .unwrap_or_default()
        };
        let chosen = self
            .choices
            .iter()
            .filter(|c| !matches!(c.setting, "select" | "refine"));
        for (k, c) in chosen.enumerate() {
            let lead = if k == 0 { "chosen" } else { "" };
            let _ = writeln!(o, "  {lead:<11} {} {}: {}", c.setting, c.value, c.why);
        }
        if self.select == Select::FreeRun {
            let _ = writeln!(
                o,
                "  select      free-run{}: the candidate with the lowest validation free-run RMSE \
                 (within 1 %: the criterion's pick) among those the estimation record excites \
                 (the validation figures below are then not an independent test)",
                auto("select")
            );
        }
        if let Some(r) = &self.refinement {
            let val = r
                .validation
                .map(|(a, b)| format!(", validation {} -> {}", num(a), num(b)))
                .unwrap_or_default();
            let _ = writeln!(
                o,
                "  refine      oe{}: {} Gauss-Newton steps, free-run RMSE estimation {} -> {}{val}: {}",
                auto("refine"),
                r.steps,
                num(r.estimation.0),
                num(r.estimation.1),
                if r.kept { "kept" } else { "discarded (not better on validation)" }
            );
        }
        let _ = writeln!(
            o,
            "  structure   p = {}, q = {}, d = {}   offset: {}",
            s.p,
            s.q,
            s.d,
            m.offset().name()
        );
        let iter_note = match self.method {
            MethodKind::RidgeM if self.iterations >= h.max_iter => " (max-iter reached)",
            MethodKind::RidgeM => " (stopped: step below tol)",
            MethodKind::Rls => " (one update per sample)",
            MethodKind::AdaptiveLasso
                if self.iterations
                    >= ridge_core_host::AdaptiveLasso::<f64>::default().max_sweeps =>
            {
                " (coordinate-descent sweeps: budget reached, not converged)"
            }
            MethodKind::AdaptiveLasso => " (coordinate-descent sweeps)",
            _ => "",
        };
        let _ = writeln!(o, "  iterations  {}{iter_note}", self.iterations);
        let _ = writeln!(
            o,
            "  score       {}   (RSS on the estimation record {})",
            num(self.score),
            num(self.rss)
        );
        let _ = writeln!(o);
        let _ = writeln!(o, "  {}", self.equation());
        let _ = writeln!(o, "  theta = {}", list(m.theta()));
        let _ = writeln!(o, "  phi   = {}", list(m.phi()));
        if m.offset() == Offset::Intercept {
            let _ = writeln!(o, "  offset = {}", num(m.intercept()));
        }
        let _ = writeln!(o, "  static gain {}", num(m.static_gain()));
        let _ = writeln!(o);
        let seed = s.seed_len();
        let _ = writeln!(
            o,
            "  Scores from measured initial conditions, as in MATLAB compare and SysIdentPy: both"
        );
        let _ = writeln!(
            o,
            "  predictors are seeded with the first m = max(p, d+q-1) = {seed} measured samples and"
        );
        let _ = writeln!(o, "  samples m..N are scored.");
        let _ = writeln!(
            o,
            "  {:<11} {:>8} {:>14} {:>14} {:>13} {:>13}",
            "record", "scored", "one-step RMSE", "free-run RMSE", "one-step fit", "free-run fit"
        );
        let mut row = |name: &str, f: &Figures| {
            let _ = writeln!(
                o,
                "  {:<11} {:>8} {:>14} {:>14} {:>12.2}% {:>12.2}%",
                name,
                f.n,
                num(f.rmse_one_step),
                num(f.rmse_free_run),
                f.fit_one_step,
                f.fit_free_run
            );
        };
        row("estimation", &self.estimation);
        if let Some(v) = &self.validation {
            row("validation", v);
        }
        let _ = writeln!(
            o,
            "  Residual analysis (one-step residuals, as MATLAB resid; 99 % bound 2.576/sqrt(N)):"
        );
        let mut resid = |name: &str, f: &Figures| {
            let Some(r) = &f.residuals else {
                let _ = writeln!(o, "  {name:<11} (none: zero residuals or constant input)");
                return;
            };
            let max = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            let _ = writeln!(
                o,
                "  {name:<11} {} (max |r_k|, k 1..25: {:.3}), {} of the input (max |c_k|, k 0..25: {:.3}); bound {:.3}",
                if r.white { "white" } else { "not white" },
                max(&r.autocorr),
                if r.independent { "independent" } else { "not independent" },
                max(&r.crosscorr),
                r.bound
            );
        };
        resid("estimation", &self.estimation);
        if let Some(v) = &self.validation {
            resid("validation", v);
        }
        if let (Some(p), Some(r)) = (&self.validate, self.validate_rows) {
            let _ = writeln!(o, "  (validation record: {}, {r} samples)", p.display());
        }
        if !self.warnings.is_empty() {
            let _ = writeln!(o);
            let _ = writeln!(o, "  warnings ({}):", self.warnings.len());
            for w in &self.warnings {
                let _ = writeln!(o, "    - {}", w.message);
            }
        }
        if let Some(c) = &self.control {
            let _ = writeln!(o);
            o.push_str(&c.to_text());
        }
        if let Some(p) = &self.plot {
            let _ = writeln!(o);
            let _ = writeln!(o, "  plot written to {}", p.display());
        }
        if let Some(p) = &self.residuals_plot {
            let _ = writeln!(o, "  residual analysis plot written to {}", p.display());
        }
        if let Some(p) = &self.control_plot {
            let _ = writeln!(o, "  closed-loop step plot written to {}", p.display());
        }
        o
    }
}
