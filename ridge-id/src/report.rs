//! The result of an identification run and its two renderings: readable text
//! ([`Report::to_text`]) and one JSON object ([`Report::to_json`]).

use std::fmt::Write as _;
use std::path::PathBuf;

use ridge_core_host::{ArxModel, Criterion, MethodKind, Offset};
use serde::Serialize;

use crate::control::ControlReport;
use crate::eval::Figures;
use crate::initial::Initial;
use crate::numfmt::{list, num, typed as hp};
use crate::options::{Hyper, Select};
use crate::phase::SegmentInfo;
use crate::refine::Refinement;
use crate::warnings::Warning;

/// How the structure was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SearchInfo {
    /// Candidates in the grid (1 with `--structure`).
    pub candidates: u16,
    /// Candidates the estimator ran on. The rest were pruned exactly: least squares
    /// minimises the RSS, so a candidate's least-squares criterion is a lower bound of its
    /// score, and candidates whose bound is worse than the best score found are skipped.
    pub evaluated: u16,
    /// Candidates that could not be fitted (too short, or not excited on this record).
    pub skipped: u16,
    /// `true` when the structure was given (`--structure`).
    pub fixed: bool,
}

/// Everything an identification run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Estimation record.
    pub input: PathBuf,
    /// Its number of samples `N`.
    pub input_rows: u32,
    /// Validation record, if any.
    pub validate: Option<PathBuf>,
    /// Its number of samples.
    pub validate_rows: Option<u32>,
    /// Estimator.
    pub method: MethodKind,
    /// Structure criterion.
    pub criterion: Criterion,
    /// The identified model (structure, θ, φ, offset).
    pub model: ArxModel<f64>,
    /// Criterion value of the model (on the validation statistics for `validation`).
    pub score: f64,
    /// Ridge-M iterates / adaptive-LASSO sweeps / 1 for closed forms / samples for RLS.
    pub iterations: u32,
    /// `‖y − Xw‖²` on the estimation record's regression rows (rows `M+1..N` from measured
    /// initial conditions, all rows with zero history: [`Hyper::initial`]).
    pub rss: f64,
    /// Hyper-parameters.
    pub hyper: Hyper,
    /// Search statistics.
    pub search: SearchInfo,
    /// Scores on the estimation record.
    pub estimation: Figures,
    /// Scores on the validation record.
    pub validation: Option<Figures>,
    /// The PNG written, if any.
    pub plot: Option<PathBuf>,
    /// The PNG of the residual analysis written (`--plot`), if any.
    pub residuals_plot: Option<PathBuf>,
    /// How the structure was chosen.
    pub select: Select,
    /// What `--refine oe` did, if asked.
    pub refinement: Option<Refinement>,
    /// Samples `M` that only filled the lag history (0 with [`Initial::Zero`]).
    pub initial_samples: u32,
    /// The controller design of `--control` (or why it was refused).
    pub control: Option<ControlReport>,
    /// The PNG of the simulated closed-loop step written (`--control --plot`), if any.
    pub control_plot: Option<PathBuf>,
    /// What should not be trusted about the model ([`crate::warnings`]); empty when all
    /// is well.
    pub warnings: Vec<Warning>,
    /// The segment of a pump's capture used as the estimation record (`--phase`), with the
    /// pump's own result for it.
    pub segment: Option<SegmentInfo>,
}

#[derive(Serialize)]
struct JsonStructure {
    p: u8,
    q: u8,
    d: u8,
}

#[derive(Serialize)]
struct JsonHyper {
    gamma: f64,
    beta: f64,
    alpha: f64,
    max_iter: u32,
    tol: f64,
    initial: &'static str,
    select: &'static str,
}

#[derive(Serialize)]
struct JsonRefine {
    method: &'static str,
    steps: u32,
    kept: bool,
    estimation_rmse_free_run: [f64; 2],
    #[serde(skip_serializing_if = "Option::is_none")]
    validation_rmse_free_run: Option<[f64; 2]>,
}

#[derive(Serialize)]
struct JsonFigures {
    n: u32,
    rmse_one_step: f64,
    rmse_free_run: f64,
    fit_free_run: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    residuals: Option<JsonResiduals>,
}

#[derive(Serialize)]
struct JsonResiduals {
    autocorr: Vec<f64>,
    crosscorr: Vec<f64>,
    bound: f64,
    white: bool,
    independent: bool,
}

impl From<&Figures> for JsonFigures {
    fn from(f: &Figures) -> Self {
        JsonFigures {
            n: f.n,
            rmse_one_step: f.rmse_one_step,
            rmse_free_run: f.rmse_free_run,
            fit_free_run: f.fit_free_run,
            residuals: f.residuals.map(|r| JsonResiduals {
                autocorr: r.autocorr.to_vec(),
                crosscorr: r.crosscorr.to_vec(),
                bound: r.bound,
                white: r.white,
                independent: r.independent,
            }),
        }
    }
}

#[derive(Serialize)]
struct Json<'a> {
    method: &'a str,
    criterion: &'a str,
    structure: JsonStructure,
    theta: &'a [f64],
    phi: &'a [f64],
    offset: f64,
    score: f64,
    iterations: u32,
    hyper: JsonHyper,
    estimation: JsonFigures,
    #[serde(skip_serializing_if = "Option::is_none")]
    validation: Option<JsonFigures>,
    #[serde(skip_serializing_if = "Option::is_none")]
    refine: Option<JsonRefine>,
    #[serde(skip_serializing_if = "Option::is_none")]
    control: Option<JsonControl<'a>>,
    warnings: Vec<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    segment: Option<serde_json::Value>,
}

#[derive(Serialize)]
#[serde(untagged)]
enum JsonControl<'a> {
    Designed {
        method: &'static str,
        ts_s: f64,
        tau_s: f64,
        alpha: f64,
        beta: f64,
        reference_s: Option<f64>,
        gamma: f64,
        kept: u8,
        tries: u8,
        modulus_margin: f64,
        mean_delay_samples: f64,
        r: &'a [f64],
        s: &'a [f64],
        t: &'a [f64],
        ao: &'a [f64],
        poles: Vec<[f64; 2]>,
    },
    Refused {
        refused: &'a str,
        check: &'static str,
        tries: u8,
        ts_s: f64,
    },
}

impl<'a> From<&'a ControlReport> for JsonControl<'a> {
    fn from(c: &'a ControlReport) -> Self {
        match &c.outcome {
            Ok(d) => JsonControl::Designed {
                method: "pole-placement",
                ts_s: c.options.ts,
                tau_s: d.design.tau,
                alpha: d.design.alpha,
                beta: d.design.beta,
                reference_s: d.reference_s,
                gamma: d.design.gamma,
                kept: d.design.kept,
                tries: d.tries,
                modulus_margin: d.design.modulus_margin,
                mean_delay_samples: d.mean_delay,
                r: &d.r,
                s: &d.s,
                t: &d.t,
                ao: d.design.rst.ao(),
                poles: d.poles.iter().map(|p| [p.re, p.im]).collect(),
            },
            Err(r) => JsonControl::Refused {
                refused: &r.reason,
                check: r.check.name(),
                tries: r.tries,
                ts_s: c.options.ts,
            },
        }
    }
}

impl Report {
    /// The JSON object of `ridge-id --json`:
    /// `{"method", "criterion", "structure": {"p","q","d"}, "theta", "phi", "offset",
    /// "score", "iterations", "hyper": {"gamma","beta","alpha","max_iter","tol","initial","select"},
    /// "estimation": {"n","rmse_one_step","rmse_free_run","fit_free_run","residuals"},
    /// "validation": {…} (only with a validation record), "refine": {"method": "oe", "steps",
    /// "kept", "estimation_rmse_free_run": [before, after], "validation_rmse_free_run":
    /// [before, after]} (only with --refine oe), "control": {…} (only with --control),
    /// "warnings": [str, …]}` (always present, empty when all is well; see
    /// [`crate::warnings`]).
    /// `offset` is the intercept (0 without one); `n` counts the scored samples `m..N`.
    /// `"residuals"` (omitted when the residuals are all zero or the input is constant):
    /// `{"autocorr": [r_1 … r_25], "crosscorr": [c_0 … c_25], "bound", "white",
    /// "independent"}`, the residual analysis of [`crate::residuals`].
    /// A non-finite number (a diverging free run) is written as `null`.
    ///
    /// `"control"` is, for a designed controller,
    /// `{"method": "pole-placement", "ts_s", "tau_s", "alpha", "beta", "reference_s", "gamma",
    /// "kept", "tries", "modulus_margin", "mean_delay_samples", "r", "s", "t", "ao", "poles":
    /// [[re, im], …]}` (`ts_s` the sample period and `tau_s` the regulation loop's time
    /// constant, s; `alpha = e^{−Ts/τ}`, `beta` the observer pole; `reference_s` the setpoint's
    /// reference model time constant (s, `null` without one) and `gamma` the setpoint
    /// response's pole (`e^{−Ts/reference_s}`, else `alpha`); `kept` model poles kept in `P`;
    /// `tries` designs made; `mean_delay_samples` of the setpoint response; `r`, `s`, `t` the
    /// controller `R u_{t+1} = T r_{t+1} − S y_t` with the reference model multiplied in
    /// ([`conventions`](crate::control::conventions): `R` and `S` carry its `1 − γ q⁻¹`) and
    /// `ao` its anti-windup observer polynomial, ascending powers of `q⁻¹`; `poles` the roots
    /// of `P = A R + q^{−d−1} B S`, by decreasing `|z|`), and for a refused one
    /// `{"refused": "reason", "check": "unstable"|"gain"|…, "tries", "ts_s"}` (see
    /// [`crate::control::Check::name`]; `tries` is 0 when the model check failed).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self.json_view()).unwrap_or(serde_json::Value::Null)
    }

    /// [`Report::to_json`] as one line of text, keys in the documented order.
    pub fn to_json_string(&self) -> String {
        serde_json::to_string(&self.json_view()).unwrap_or_else(|_| "null".to_string())
    }

    fn json_view(&self) -> Json<'_> {
        let s = self.model.structure();
        Json {
            method: self.method.name(),
            criterion: self.criterion.name(),
            structure: JsonStructure {
                p: s.p,
                q: s.q,
                d: s.d,
            },
            theta: self.model.theta(),
            phi: self.model.phi(),
            offset: self.model.intercept(),
            score: self.score,
            iterations: self.iterations,
            hyper: JsonHyper {
                gamma: self.hyper.gamma,
                beta: self.hyper.beta,
                alpha: self.hyper.alpha,
                max_iter: self.hyper.max_iter,
                tol: self.hyper.tol,
                initial: self.hyper.initial.name(),
                select: self.select.name(),
            },
            estimation: JsonFigures::from(&self.estimation),
            validation: self.validation.as_ref().map(JsonFigures::from),
            refine: self.refinement.map(|r| JsonRefine {
                method: "oe",
                steps: r.steps,
                kept: r.kept,
                estimation_rmse_free_run: [r.estimation.0, r.estimation.1],
                validation_rmse_free_run: r.validation.map(|v| [v.0, v.1]),
            }),
            control: self.control.as_ref().map(JsonControl::from),
            warnings: self.warnings.iter().map(|w| w.message.as_str()).collect(),
            segment: self.segment.as_ref().map(|s| s.to_json(&self.model)),
        }
    }

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
        let method = match self.method {
            MethodKind::RidgeM => format!(
                "ridge-m (gamma {}, beta {}, tol {}, max-iter {})",
                hp(h.gamma),
                hp(h.beta),
                hp(h.tol),
                h.max_iter
            ),
            MethodKind::Ridge => format!("ridge (gamma {})", hp(h.gamma)),
            MethodKind::Ols => "ols (least squares)".to_string(),
            MethodKind::Rls => format!(
                "rls (lambda {}, delta {}); structure from a ridge-m search (gamma {}, beta {}, tol {}, max-iter {})",
                hp(h.lambda),
                hp(h.delta),
                hp(h.gamma),
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
        if self.select == Select::FreeRun {
            let _ = writeln!(
                o,
                "  select      free-run: the candidate with the lowest validation free-run RMSE \
                 (the validation figures below are then not an independent test)"
            );
        }
        if let Some(r) = &self.refinement {
            let val = r
                .validation
                .map(|(a, b)| format!(", validation {} -> {}", num(a), num(b)))
                .unwrap_or_default();
            let _ = writeln!(
                o,
                "  refine      oe: {} Gauss-Newton steps, free-run RMSE estimation {} -> {}{val}: {}",
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
