//! The JSON printer: a [`Report`] as one JSON object ([`Report::to_json`],
//! [`Report::to_json_string`]), keys in the documented order.

use ridge_core_host::ArxModel;
use serde::Serialize;

use crate::control::ControlReport;
use crate::eval::Figures;
use crate::outcome::Report;
use crate::phase::{Agreement, SegmentInfo};

#[derive(Serialize)]
struct JsonStructure {
    p: u8,
    q: u8,
    d: u8,
}

#[derive(Serialize)]
struct JsonHyper {
    gamma: f64,
    gamma_scale: &'static str,
    beta: f64,
    alpha: f64,
    max_iter: u32,
    tol: f64,
    initial: &'static str,
    select: &'static str,
}

#[derive(Serialize)]
struct JsonStandardised {
    sigma_u: f64,
    sigma_y: f64,
}

#[derive(Serialize)]
struct JsonChoice<'a> {
    setting: &'a str,
    value: &'a str,
    why: &'a str,
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
    #[serde(skip_serializing_if = "Option::is_none")]
    standardised: Option<JsonStandardised>,
    choices: Vec<JsonChoice<'a>>,
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
    /// "score", "iterations",
    /// "hyper": {"gamma","gamma_scale","beta","alpha","max_iter","tol","initial","select"},
    /// "standardised": {"sigma_u","sigma_y"} (only when the estimator ran on the standardised
    /// record), "choices": [{"setting","value","why"}, …] (what the run chose for the user, see
    /// [`crate::outcome::Choice`]; always present),
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
                gamma_scale: self.hyper.gamma_scale.name(),
                beta: self.hyper.beta,
                alpha: self.hyper.alpha,
                max_iter: self.hyper.max_iter,
                tol: self.hyper.tol,
                initial: self.hyper.initial.name(),
                select: self.select.name(),
            },
            standardised: self
                .standardised
                .map(|(sigma_u, sigma_y)| JsonStandardised { sigma_u, sigma_y }),
            choices: self
                .choices
                .iter()
                .map(|c| JsonChoice {
                    setting: c.setting,
                    value: &c.value,
                    why: &c.why,
                })
                .collect(),
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
}

impl SegmentInfo {
    /// The `"segment"` object of the JSON report.
    pub fn to_json(&self, model: &ArxModel<f64>) -> serde_json::Value {
        #[derive(Serialize)]
        struct Device<'a> {
            line: u64,
            structure: [u8; 3],
            offset: bool,
            theta: &'a [f64],
            phi: &'a [f64],
            c: f64,
            iterations: Option<u32>,
            agreement: Agreement,
        }
        #[derive(Serialize)]
        struct Json<'a> {
            phase: &'a str,
            index: u32,
            count: u32,
            lines: [u64; 2],
            excite_line: Option<u64>,
            /// The `# MAP` line the input went through: its line, first knot and spacing
            /// (duty fraction), and its 16 flows (slm).
            map: Option<Map>,
            operating_point: Option<[f64; 2]>,
            device: Option<Device<'a>>,
        }
        #[derive(Serialize)]
        struct Map {
            line: u64,
            first: f64,
            step: f64,
            flow: Vec<f64>,
        }
        let j = Json {
            phase: &self.phase,
            index: self.index,
            count: self.count,
            lines: [self.lines.0, self.lines.1],
            excite_line: self.excite.as_ref().map(|e| e.line),
            map: self.map.as_ref().map(|m| Map {
                line: m.line,
                first: f64::from(m.map.first()) / 10_000.0,
                step: f64::from(m.map.step()) / 10_000.0,
                flow: m
                    .map
                    .knots()
                    .iter()
                    .map(|k| f64::from(*k) / 120.0)
                    .collect(),
            }),
            operating_point: self.operating_point.map(|(u, y)| [u, y]),
            device: self.device.as_ref().map(|d| Device {
                line: d.line,
                structure: [d.p, d.q, d.d],
                offset: d.offset,
                theta: &d.theta,
                phi: &d.phi,
                c: d.c,
                iterations: d.iterations,
                agreement: d.agreement(model),
            }),
        };
        serde_json::to_value(j).unwrap_or(serde_json::Value::Null)
    }
}
