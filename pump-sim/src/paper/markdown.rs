//! Markdown rendering of the [`Tables`]: what `paper-tables` prints.

use std::fmt::Write as _;

use ridge_core::{Criterion, MethodKind, Offset, Structure};

use super::{
    Comparison, Convergence, Rmse, Sweep, Tables, ALPHA, CRITERIA, GAMMA, RECORDS, RLS_DELTA,
    RLS_LAMBDA,
};

fn st(s: Structure) -> String {
    format!("({}, {}, {})", s.p, s.q, s.d)
}

fn coef_list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.4}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn comparison_md(out: &mut String, title: &str, c: &Comparison) {
    let _ = writeln!(
        out,
        "### {title}: identified on {}, criterion `{}`, offset `{}`\n",
        c.identification.name(),
        c.criterion.name(),
        c.offset.name()
    );
    let _ = writeln!(
        out,
        "Ridge-M + search (criterion `{}`, α = {ALPHA}, γ = {GAMMA}, β = 0.01, 200 iterates, ε = 1e-6) picks \
         **ARX{}** (true plant delay: 3 samples); Ridge-M ran on {} of {} candidates and used {} \
         iterates on the pick.\n",
        c.criterion.name(),
        st(c.structure),
        c.evaluated,
        c.candidates,
        c.ridge_m_iterations
    );
    for (label, free) in [
        ("Free-run RMSE (slm)", true),
        ("One-step RMSE (slm)", false),
    ] {
        let _ = writeln!(out, "{label}:\n");
        let _ = write!(out, "| Input function |");
        for e in &c.estimates {
            let _ = write!(out, " {} |", e.method.name());
        }
        let _ = writeln!(out);
        let _ = write!(out, "|---|");
        for _ in &c.estimates {
            let _ = write!(out, "---:|");
        }
        let _ = writeln!(out);
        let val = |r: &Rmse| if free { r.free_run } else { r.one_step };
        for (ri, r) in RECORDS.iter().enumerate() {
            let _ = write!(out, "| {} |", r.name());
            for e in &c.estimates {
                let _ = write!(out, " {:.4} |", val(&e.rmse[ri]));
            }
            let _ = writeln!(out);
        }
        let _ = write!(out, "| **Average** |");
        for e in &c.estimates {
            let _ = write!(out, " **{:.4}** |", val(&e.average()));
        }
        let _ = writeln!(out, "\n");
    }
    let _ = writeln!(
        out,
        "Coefficients (θ₁…θ_p | φ₀…φ_q₋₁{}):\n",
        if c.offset == Offset::Intercept {
            " | c"
        } else {
            ""
        }
    );
    for e in &c.estimates {
        let m = &e.model;
        let _ = write!(
            out,
            "- `{}`: θ = [{}], φ = [{}]",
            e.method.name(),
            coef_list(m.theta()),
            coef_list(m.phi())
        );
        if c.offset == Offset::Intercept {
            let _ = write!(out, ", c = {:.4}", m.intercept());
        }
        let _ = writeln!(out, ", static gain {:.1} slm/duty", m.static_gain());
    }
    let _ = writeln!(
        out,
        "\nAll models are scored by `ridge_core::Evaluation`: both predictors are seeded with the \
         first m = max(p, d+q−1) = {} measured samples and scored on samples m..N, not from \
         the zero history used for estimation. `{}`: λ = {RLS_LAMBDA}, \
         δ = {RLS_DELTA}, one update per sample over the whole record, final estimate. `{}`: \
         weights 1/|w_OLS|, λ by BIC over a 30-point path. `{}` is a reference column, not in \
         the paper.\n",
        c.structure.seed_len(),
        MethodKind::Rls.name(),
        MethodKind::AdaptiveLasso.name(),
        MethodKind::Ols.name()
    );
}

fn sweep_md(out: &mut String, s: &Sweep) {
    let _ = writeln!(
        out,
        "### Table 4 (criterion `{}`): γ sweep, identified on {}, validated on {}\n",
        s.criterion.name(),
        s.identification.name(),
        s.validation.name()
    );
    let _ = writeln!(
        out,
        "| γ | free-run RMSE | one-step RMSE | (p, q, d) | | free-run RMSE | one-step RMSE | (p, q, d) | iterates | theory: γ/(λ+γ)·ρ¹⁹⁹ |"
    );
    let _ = writeln!(out, "|---:|---:|---:|:---:|---|---:|---:|:---:|---:|---:|");
    let _ = writeln!(
        out,
        "| | **without momentum (`{}`)** | | | | **with momentum (`{}`)** | | | | |",
        MethodKind::Ridge.name(),
        MethodKind::RidgeM.name()
    );
    let o = &s.ols;
    let _ = writeln!(
        out,
        "| `{}` (γ = 0) | {:.4} | {:.4} | {} | | | | | | |",
        MethodKind::Ols.name(),
        o.rmse.free_run,
        o.rmse.one_step,
        st(o.structure)
    );
    for r in &s.rows {
        let _ = writeln!(
            out,
            "| 1e{} | {:.4} | {:.4} | {} | | {:.4} | {:.4} | {} | {} | {:.2e} |",
            r.gamma.log10().round() as i32,
            r.plain.rmse.free_run,
            r.plain.rmse.one_step,
            st(r.plain.structure),
            r.momentum.rmse.free_run,
            r.momentum.rmse.one_step,
            st(r.momentum.structure),
            r.momentum.iterations,
            r.residual_factor
        );
    }
    let _ = writeln!(
        out,
        "\nRMSE in slm on {}, predictors seeded with the first m = max(p, d+q−1) measured samples \
         and scored on samples m..N. \"iterates\": Ridge-M \
         iterates on the pick (200 = stopped by max_iter, not by ε = 1e-6). Theory column: after \
         200 iterates Ridge-M differs from least squares by the factor γ/(λ+γ)·ρ¹⁹⁹, \
         ρ = β + (1−β)γ/(λ+γ), in the eigen-mode λ of XᵀX; shown for the smallest eigenvalue \
         of any candidate, λ_min = {:.4} at ARX{} (largest eigenvalues ~1e8). Where it is ≪ 1, \
         Ridge-M is least squares on every candidate and must pick what OLS picks.\n",
        s.validation.name(),
        s.lambda_min.0,
        st(s.lambda_min.1)
    );
}

fn convergence_md(out: &mut String, crit: Criterion, c: &Convergence, table: u8) {
    let s = c.structure;
    let _ = writeln!(
        out,
        "### Table {table} (criterion `{}`): Ridge-M coefficients vs iteration, γ = {}, ARX{} on \
         A-Multistep\n",
        crit.name(),
        c.gamma,
        st(s)
    );
    let _ = write!(out, "| Iteration |");
    for i in 1..=s.p {
        let _ = write!(out, " θ{i} |");
    }
    for j in 0..s.q {
        let _ = write!(out, " φ{j} |");
    }
    let _ = writeln!(out);
    let _ = write!(out, "|---:|");
    for _ in 0..(s.p + s.q) {
        let _ = write!(out, "---:|");
    }
    let _ = writeln!(out);
    let rows = c
        .rows
        .iter()
        .map(|(k, m)| (k.to_string(), m))
        .chain(std::iter::once((
            format!("`{}`", MethodKind::Ols.name()),
            &c.ols,
        )));
    for (k, m) in rows {
        let _ = write!(out, "| {k} |");
        for v in m.theta().iter().chain(m.phi()) {
            let _ = write!(out, " {v:.4} |");
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "\nβ = 0.01, tolerance 0 (every iterate runs). Row `{}` is the least-squares solution, \
         the fixed point of the iteration.\n",
        MethodKind::Ols.name()
    );
}

impl Tables {
    /// The tables as markdown (what `paper-tables` prints).
    pub fn to_markdown(&self) -> String {
        let mut out = String::new();
        intro_md(&mut out, self);
        records_md(&mut out, self);
        picks_md(&mut out, self);
        for c in &self.table1 {
            comparison_md(&mut out, "Table 1", c);
        }
        for c in &self.table5 {
            comparison_md(&mut out, "Table 5", c);
        }
        comparison_md(&mut out, "Table 1 with intercept", &self.intercept);
        for s in &self.table4 {
            sweep_md(&mut out, s);
        }
        for (crit, tables) in &self.convergence {
            for (c, n) in tables.iter().zip([2u8, 3]) {
                convergence_md(&mut out, *crit, c, n);
            }
        }
        pruning_md(&mut out, self);
        precision_md(&mut out, self);
        forgetting_md(&mut out, self);
        census_md(&mut out, self);
        out
    }
}

fn intro_md(out: &mut String, r: &Tables) {
    let _ = writeln!(
        out,
        "## Paper tables on the simulated pump (seed {})\n\n\
         Records: `pump_sim::record(Record::…, &PumpParams::default(), {})`, 3000 samples \
         at 100 Hz each (reference blower: dead zone 12–15 % duty, τ = 0.15 s, flow ∝ speed^1.3, \
         150 slm at full duty, transport delay 3 samples; SFM3300 noise 3 % of reading). \
         Statistics: `IntGram::push(raw_u, raw_y − 32768)`, `SCALE`, solved \
         in f64. Coefficients in slm and duty fraction (0..1). Grid p ∈ 1..6, q ∈ 1..6, \
         d ∈ 0..6 (252 candidates).\n",
        r.seed, r.seed
    );
    let _ = writeln!(
        out,
        "Criteria, offsets and estimators are named as in `ridge_core` (`Criterion`, `Offset`, \
         `MethodKind`): criterion `{}` is the paper's eq. (14), N ln(RSS/N) + α(p+q+d); `{}` is \
         the delay-free AIC, N ln(RSS/N) + α(p+q). Offset `{}` is the paper's model without a \
         constant term; `{}` adds one. Estimators: `{}` (the paper's Ridge-M), `{}` (plain \
         Ridge), `{}`, `{}` (adaptive LASSO) and `{}` (least squares).\n",
        Criterion::Paper.name(),
        Criterion::Aic.name(),
        Offset::None.name(),
        Offset::Intercept.name(),
        MethodKind::RidgeM.name(),
        MethodKind::Ridge.name(),
        MethodKind::Rls.name(),
        MethodKind::AdaptiveLasso.name(),
        MethodKind::Ols.name()
    );
}

fn records_md(out: &mut String, r: &Tables) {
    let _ = writeln!(out, "### Records\n");
    let _ = writeln!(
        out,
        "| Record | N | duty range | duty changes | flow mean (slm) | flow std (slm) | \
         flow range (slm) | sensor noise RMS (slm) |"
    );
    let _ = writeln!(out, "|---|---:|:---:|---:|---:|---:|:---:|---:|");
    for x in &r.records {
        let _ = writeln!(
            out,
            "| {} | {} | {:.2}–{:.2} | {} | {:.2} | {:.2} | {:.2}–{:.2} | {:.2} |",
            x.record.name(),
            x.samples,
            x.u_range.0,
            x.u_range.1,
            x.u_changes,
            x.y_mean,
            x.y_std,
            x.y_range.0,
            x.y_range.1,
            x.noise_rms
        );
    }
    let _ = writeln!(
        out,
        "\n\"duty changes\": samples with u_t ≠ u_(t−1), the only samples at which delays d and \
         d+1 give different regressors. On a ramp the difference u_(t−d) − u_(t−d−1) is the \
         constant slope almost everywhere, which a neighbouring input lag absorbs: ramps carry \
         almost no information about d.\n"
    );
}

/// The structures picked in Tables 1 and 5, one column per criterion of [`CRITERIA`].
fn picks_md(out: &mut String, r: &Tables) {
    let _ = writeln!(out, "### Structures picked by the Ridge-M search\n");
    let _ = write!(out, "| Identification record |");
    for c in CRITERIA {
        let _ = write!(out, " `{}` |", c.name());
    }
    let _ = write!(out, "\n|---|");
    for _ in CRITERIA {
        let _ = write!(out, ":---:|");
    }
    let _ = writeln!(out);
    let rows = [
        (
            String::from("A-Multistep"),
            r.table1.iter().collect::<Vec<_>>(),
        ),
        (String::from("A-Ramp"), r.table5.iter().collect()),
        (
            format!("A-Multistep, offset `{}`", r.intercept.offset.name()),
            vec![&r.intercept],
        ),
    ];
    for (name, comparisons) in rows {
        let _ = write!(out, "| {name} |");
        for c in CRITERIA {
            match comparisons.iter().find(|t| t.criterion == c) {
                Some(t) => {
                    let _ = write!(out, " {} |", st(t.structure));
                }
                None => {
                    let _ = write!(out, " — |");
                }
            }
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "\nTrue transport delay of the simulated plant: d = 3. The paper reports (5, 6, 4) on its \
         A-Multistep and (5, 1, 0) on its A-Ramp.\n"
    );
}

fn pruning_md(out: &mut String, r: &Tables) {
    let _ = writeln!(
        out,
        "### Pruned search vs exhaustive grid (A-Multistep, Ridge-M)\n"
    );
    let _ = writeln!(
        out,
        "| Criterion | Offset | pruned pick | Ridge-M runs (pruned) | exhaustive pick | \
         Ridge-M runs (exhaustive) | same score |"
    );
    let _ = writeln!(out, "|---|---|:---:|---:|:---:|---:|:---:|");
    for p in &r.pruning {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} of {} | {} | {} | {} |",
            p.criterion.name(),
            p.offset.name(),
            st(p.pruned),
            p.evaluated,
            p.candidates,
            st(p.exhaustive),
            p.exhaustive_evaluated,
            if p.same_score { "yes" } else { "no" }
        );
    }
    let _ = writeln!(out);
}

fn precision_md(out: &mut String, r: &Tables) {
    let _ = writeln!(
        out,
        "### f32 vs f64 solves on the same integer statistics (A-Multistep, Ridge-M)\n"
    );
    let _ = writeln!(
        out,
        "| Criterion | f64 pick | f32 pick | Ridge-M runs f64 / f32 | max abs coef diff | \
         max abs coef | free-run RMSE f64 / f32 |"
    );
    let _ = writeln!(out, "|---|:---:|:---:|---:|---:|---:|---:|");
    for p in &r.precision {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} / {} | {:.3e} | {:.4} | {:.4} / {:.4} |",
            p.criterion.name(),
            st(p.structure_f64),
            st(p.structure_f32),
            p.evaluated.0,
            p.evaluated.1,
            p.max_coef_diff,
            p.max_coef,
            p.free_run.0,
            p.free_run.1
        );
    }
    let _ = writeln!(
        out,
        "\nCoefficient difference: Ridge-M fitted in f32 and in f64 on the f64 pick; the f32 model \
         is scored in f64 arithmetic.\n"
    );
}

fn forgetting_md(out: &mut String, r: &Tables) {
    let f = &r.forgetting;
    let _ = writeln!(
        out,
        "### RLS forgetting factor (A-Multistep, ARX{}, final estimate, mean over the four \
         records)\n",
        st(f.structure)
    );
    let _ = writeln!(out, "| λ | mean free-run RMSE | mean one-step RMSE |");
    let _ = writeln!(out, "|---:|---:|---:|");
    for (l, m) in &f.rows {
        let _ = writeln!(out, "| {l} | {:.4} | {:.4} |", m.free_run, m.one_step);
    }
    let _ = writeln!(out);
}

fn census_md(out: &mut String, r: &Tables) {
    if let Some(first) = r.census.first() {
        let _ = writeln!(
            out,
            "### Seed census: picks over {} sensor-noise seeds ({}..{})\n",
            first.seeds,
            r.seed,
            r.seed.wrapping_add(u64::from(first.seeds) - 1)
        );
    }
    let _ = writeln!(
        out,
        "| Record | Criterion | Offset | Estimator | d = 0 | 1 | 2 | 3 | 4 | 5 | 6 | \
         d = 0 or q = 6 | most frequent pick |"
    );
    let _ = writeln!(
        out,
        "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|:---|"
    );
    for c in &r.census {
        let _ = write!(
            out,
            "| {} | {} | {} | {} |",
            c.record.name(),
            c.criterion.name(),
            c.offset.name(),
            c.method.name()
        );
        for n in c.d_counts {
            let _ = write!(out, " {n} |");
        }
        let _ = writeln!(
            out,
            " {} of {} | {} ×{} |",
            c.flaw_pattern,
            c.seeds,
            st(c.mode.0),
            c.mode.1
        );
    }
    let _ = writeln!(
        out,
        "\nTrue delay 3. \"d = 0 or q = 6\": the pattern the paper criterion must follow with least \
         squares, since (p, q+d, 0) contains every regressor of (p, q, d) at the same penalty \
         α(p+q+d) of the paper's eq. (14), so it fits at least as well.\n"
    );
}
