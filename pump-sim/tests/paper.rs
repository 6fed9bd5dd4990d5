//! The paper experiments (`pump_sim::paper`) checked against independent truth: the
//! simulator's true transport delay, the nesting argument behind the paper criterion's flaw,
//! the closed-form convergence of Ridge-M to least squares, and the RLS/Ridge identity.

use nalgebra::{DMatrix, DVector};
use pump_sim::paper::{
    comparison, convergence, gamma_sweep, gram_matrix, int_gram, precision, pruning,
    ridge_m_residual_factor, rls, search, symmetric_eigenvalues, Comparison, Dataset, COMPARED,
    DEFAULT_SEED, RLS_DELTA,
};
use pump_sim::{record, PumpParams};
use ridge_core::{
    ArxModel, Criterion, Estimator, Grid, Method, MethodKind, Normal, Offset, Ols, Ridge, RidgeM,
    Search, Structure, Q_MAX,
};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::SCALE;

/// The simulator's transport delay: the independent truth for the delay picks.
const TRUE_DELAY: u8 = 3;

fn normal_of(r: Record, seed: u64) -> Normal<f64> {
    let log = record(r, &PumpParams::default(), seed);
    int_gram(&log).unwrap().normal::<f64>(SCALE).unwrap()
}

fn ridge_m_pick(n: &Normal<f64>, c: Criterion, o: Offset) -> Structure {
    search(n, c, o, Method::RidgeM(RidgeM::default()), true)
        .unwrap()
        .structure()
}

fn coefs(m: &ArxModel<f64>) -> Vec<f64> {
    m.theta().iter().chain(m.phi()).copied().collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// The criterion value of one structure (a one-candidate search).
fn score_of(n: &Normal<f64>, s: Structure, c: Criterion, o: Offset) -> f64 {
    Search {
        grid: Grid::single(s),
        criterion: c,
        offset: o,
        ..Search::default()
    }
    .run(n, None)
    .unwrap()
    .score
}

#[test]
fn the_simulated_plant_has_the_delay_the_tests_assume() {
    assert_eq!(PumpParams::default().delay_samples, usize::from(TRUE_DELAY));
}

/// (1) The delay-free AIC on A-Multistep. What holds: with an intercept (the dead zone makes
/// the duty→flow map affine, not proportional) it finds d = 3 on every seed; without one, a
/// proportional model is biased and the pick is d = 3 on most seeds but d = 4 on some,
/// including the default seed. The delay is identified only at the 14 duty steps of the
/// record (u_{t−3} and u_{t−4} differ only there), so the evidence for d = 3 over d = 4 is
/// a few AIC units, below one parameter's penalty.
#[test]
fn delay_free_aic_finds_the_true_delay_with_an_intercept_and_within_one_sample_without() {
    let seeds = 16u64;
    let mut exact_without = 0;
    for i in 0..seeds {
        let n = normal_of(Record::AMultistep, DEFAULT_SEED + i);
        let with = ridge_m_pick(&n, Criterion::Aic, Offset::Intercept);
        assert_eq!(with.d, TRUE_DELAY, "seed +{i}: intercept pick {with:?}");
        let without = ridge_m_pick(&n, Criterion::Aic, Offset::None);
        assert!(
            without.d == TRUE_DELAY || without.d == TRUE_DELAY + 1,
            "seed +{i}: no-offset pick {without:?}"
        );
        exact_without += u32::from(without.d == TRUE_DELAY);
    }
    assert!(
        exact_without * 4 >= 3 * seeds as u32,
        "no-offset AIC found d = 3 on only {exact_without} of {seeds} seeds"
    );

    // The default seed is one of the d = 4 cases: the scores of the two delays are close.
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    let log = data.log(Record::AMultistep).unwrap();
    let steps = log.raw_u.windows(2).filter(|w| w[0] != w[1]).count();
    assert_eq!(steps, 14, "A-Multistep has 15 levels");
    let n = data.normal::<f64>(Record::AMultistep).unwrap();
    let pick = ridge_m_pick(&n, Criterion::Aic, Offset::None);
    assert_eq!((pick.d, pick.q), (TRUE_DELAY + 1, 6));
    let at_true = Structure {
        d: TRUE_DELAY,
        ..pick
    };
    let gap = score_of(&n, at_true, Criterion::Aic, Offset::None)
        - score_of(&n, pick, Criterion::Aic, Offset::None);
    assert!(gap > 0.0 && gap < 12.0, "AIC gap d=3 vs d=4: {gap}");

    // A PRBS (hundreds of input transitions) with an intercept finds the delay on every seed.
    for i in 0..4 {
        let n = normal_of(Record::Prbs, DEFAULT_SEED + i);
        assert_eq!(
            ridge_m_pick(&n, Criterion::Aic, Offset::Intercept).d,
            TRUE_DELAY
        );
    }
}

/// (2) The paper's criterion counts d as a parameter, so (p, q + d, 0), which contains every
/// regressor of (p, q, d) at the same penalty, fits at least as well: with least squares its
/// pick always has d = 0 or q at the maximum. With Ridge-M (200 iterates, not converged on
/// long input lags) that argument is not exact; on the default records it still holds.
#[test]
fn paper_criterion_picks_d_zero_or_q_max() {
    let flaw = |s: Structure| s.d == 0 || usize::from(s.q) == Q_MAX;
    for r in [Record::AMultistep, Record::ARamp, Record::Prbs] {
        for i in 0..4 {
            let n = normal_of(r, DEFAULT_SEED + i);
            for o in [Offset::None, Offset::Intercept] {
                let s = search(&n, Criterion::Paper, o, Method::Ols, true)
                    .unwrap()
                    .structure();
                assert!(flaw(s), "{} seed +{i} {o:?}: OLS pick {s:?}", r.name());
            }
            // The nesting itself: least-squares RSS of (p, q+d, 0) ≤ that of (p, q, d).
            if i == 0 {
                for s in Grid::default().iter().filter(|s| s.d > 0) {
                    if usize::from(s.q + s.d) > Q_MAX {
                        continue;
                    }
                    let big = Structure {
                        q: s.q + s.d,
                        d: 0,
                        ..s
                    };
                    let rss =
                        |s: Structure| Ols.fit(&n.system(s, Offset::None).unwrap()).unwrap().rss;
                    assert!(rss(big) <= rss(s) * (1.0 + 1e-12), "{s:?} vs {big:?}");
                }
            }
        }
    }
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    for r in [Record::AMultistep, Record::ARamp] {
        let c = comparison(&data, r, Criterion::Paper, Offset::None).unwrap();
        assert!(flaw(c.structure), "{}: {:?}", r.name(), c.structure);
    }
}

/// (3) Table 4. γ → 0: Ridge, Ridge-M and least squares coincide. Ridge-M's fixed point is
/// least squares; after 200 iterates it is within the factor γ/(λ+γ)·ρ¹⁹⁹ of it in every
/// eigen-mode (closed form of the paper's eqs. (10) and (12), see
/// `paper::ridge_m_residual_factor`): where that factor is tiny for the smallest eigenvalue
/// of every candidate, the momentum pick must be the least-squares pick.
#[test]
fn gamma_sweep_small_gamma_is_least_squares_and_momentum_pick_is_ols_while_converged() {
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    for c in [Criterion::Paper, Criterion::Aic] {
        let sw = gamma_sweep(&data, Record::AMultistep, Record::BRamp, c).unwrap();
        let first = &sw.rows[0];
        assert_eq!(first.gamma, 0.1);
        for p in [&first.plain, &first.momentum] {
            assert_eq!(p.structure, sw.ols.structure, "{c:?}");
            assert!(
                rel(p.rmse.free_run, sw.ols.rmse.free_run) < 1e-3,
                "{c:?} {p:?}"
            );
            assert!(
                rel(p.rmse.one_step, sw.ols.rmse.one_step) < 1e-3,
                "{c:?} {p:?}"
            );
        }
        let converged: Vec<_> = sw
            .rows
            .iter()
            .filter(|r| r.residual_factor < 1e-3)
            .collect();
        assert!(
            converged.len() >= 3,
            "{c:?}: only {} converged γ",
            converged.len()
        );
        for r in converged {
            assert_eq!(
                r.momentum.structure, sw.ols.structure,
                "{c:?} γ = {}",
                r.gamma
            );
            assert!(rel(r.momentum.rmse.free_run, sw.ols.rmse.free_run) < 1e-3);
        }
        // Where the theory says 200 iterates are far from enough, Ridge-M used them all.
        for r in sw.rows.iter().filter(|r| r.residual_factor > 0.1) {
            assert_eq!(r.momentum.iterations, 200, "{c:?} γ = {}", r.gamma);
        }

        // The smallest eigenvalue is right: XᵀX − 0.99 λ_min I is positive definite,
        // XᵀX − 1.01 λ_min I is not.
        let (lmin, s) = sw.lambda_min;
        let n = data.normal::<f64>(Record::AMultistep).unwrap();
        let g = gram_matrix(&n.system(s, Offset::None).unwrap());
        assert!(cholesky_ok(&g, 0.99 * lmin));
        assert!(!cholesky_ok(&g, 1.01 * lmin));
    }
}

/// Whether `a − shift·I` is positive definite: a plain Cholesky factorisation, independent of
/// the eigen-solver.
fn cholesky_ok(a: &DMatrix<f64>, shift: f64) -> bool {
    let n = a.nrows();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[(i, j)] - if i == j { shift } else { 0.0 };
            s -= (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s <= 0.0 {
                    return false;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    true
}

/// The eigen-solver on matrices whose eigenvalues are known by construction:
/// `A = H Λ H` with a Householder reflection `H = I − 2vvᵀ/(vᵀv)` (symmetric, orthogonal), so
/// the eigenvalues of `A` are the diagonal of `Λ`. The spread 0.5 … 8e7 is that of the pump's
/// Gram matrices (smallest eigenvalue ~0.5, largest ~1e8).
#[test]
fn symmetric_eigenvalues_recovers_known_eigenvalues() {
    let lambda = [8e7, 0.5, 2e5, 3.0, 1e3, 40.0, 0.5];
    let n = lambda.len();
    let v = DVector::from_fn(n, |i, _| {
        1.0 + i as f64 * 0.7 - if i % 2 == 1 { 2.5 } else { 0.0 }
    });
    let h = DMatrix::<f64>::identity(n, n) - &v * v.transpose() * (2.0 / v.dot(&v));
    let a = &h * DMatrix::from_diagonal(&DVector::from_row_slice(&lambda)) * &h;
    let got = symmetric_eigenvalues(&a);
    let mut want = lambda.to_vec();
    want.sort_by(f64::total_cmp);
    assert_eq!(got.len(), n);
    for (g, w) in got.iter().zip(&want) {
        // Backward-stable solver: absolute error ~ ε · ‖A‖ = 2e-16 · 8e7.
        assert!((g - w).abs() < 1e-6 * w.max(1.0), "{got:?} vs {want:?}");
    }
    // A diagonal matrix, given unsorted: its diagonal, ascending.
    let d = DMatrix::from_diagonal(&DVector::from_row_slice(&[3.0, -1.0, 2.0]));
    assert_eq!(symmetric_eigenvalues(&d), vec![-1.0, 2.0, 3.0]);
}

/// (4) Tables 2–3: iterates settle (late steps smaller than early ones) and approach least
/// squares monotonically (every eigen-mode of the error shrinks by ρ < 1 per iterate); the
/// distance after k iterates obeys the closed-form bound.
#[test]
fn ridge_m_iterates_converge_monotonically_to_least_squares() {
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    let n = data.normal::<f64>(Record::AMultistep).unwrap();
    let s = ridge_m_pick(&n, Criterion::Paper, Offset::None);
    let all: Vec<u32> = (1..=180).collect();
    for gamma in [100.0, 1000.0] {
        let c = convergence(&data, Record::AMultistep, s, gamma, &all).unwrap();
        assert_eq!(c.rows.len(), 180);
        let w = |k: u32| coefs(&c.rows[(k - 1) as usize].1);
        let early = norm(&diff(&w(30), &w(1)));
        let late = norm(&diff(&w(180), &w(150)));
        assert!(
            late < early,
            "γ = {gamma}: |w180−w150| {late} vs |w30−w1| {early}"
        );
        let ls = coefs(&c.ols);
        let mut prev = f64::INFINITY;
        for k in 1..=180 {
            let e = norm(&diff(&w(k), &ls));
            assert!(
                e <= prev * (1.0 + 1e-9),
                "γ = {gamma}: error grew at k = {k}"
            );
            prev = e;
        }
        // Closed form: ‖w_k − w_LS‖ ≤ max_i γ/(λ_i+γ) ρ_i^{k−1} ‖w_LS‖, largest at λ_min.
        let g = gram_matrix(&n.system(s, Offset::None).unwrap());
        let lmin = symmetric_eigenvalues(&g)[0];
        assert!(cholesky_ok(&g, 0.99 * lmin) && !cholesky_ok(&g, 1.01 * lmin));
        let bound = ridge_m_residual_factor(lmin, gamma, 0.01, 180) * norm(&ls);
        assert!(
            prev <= bound * (1.0 + 1e-6),
            "γ = {gamma}: {prev} > bound {bound}"
        );
        // …and it is not reached yet at γ = 1000: the paper's "settled by 180" needs a
        // better-conditioned XᵀX than 100 Hz lags of this pump give.
        if gamma == 1000.0 {
            assert!(
                prev > 0.1 * norm(&ls),
                "γ = 1000 converged unexpectedly: {prev}"
            );
        }
    }
}

fn diff(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

/// (5) RLS with λ = 1 from P₀ = δI minimises ‖y − Xw‖² + ‖w‖²/δ: it is Ridge with γ = 1/δ
/// (to rounding) and ends close to least squares.
#[test]
fn rls_without_forgetting_is_ridge_with_gamma_one_over_delta_and_ends_at_least_squares() {
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    let log = data.log(Record::AMultistep).unwrap();
    let n = data.normal::<f64>(Record::AMultistep).unwrap();
    for s in [
        Structure::new(6, 6, 4).unwrap(),
        Structure::new(2, 2, 3).unwrap(),
        Structure::new(6, 1, 0).unwrap(),
    ] {
        let sys = n.system(s, Offset::None).unwrap();
        let ols = Ols.fit(&sys).unwrap();
        let ridge = Ridge {
            gamma: 1.0 / RLS_DELTA,
        }
        .fit(&sys)
        .unwrap();
        let r = rls(log, s, Offset::None, 1.0, RLS_DELTA).unwrap();
        let (cr, co) = (coefs(&r), coefs(&ols.model()));
        let scale = co.iter().map(|x| x.abs()).fold(0.0, f64::max);
        assert!(
            max_abs_diff(&cr, &coefs(&ridge.model())) < 1e-9 * scale,
            "{s:?}: RLS vs Ridge(1/δ)"
        );
        assert!(max_abs_diff(&cr, &co) < 2e-3 * scale, "{s:?}: RLS vs OLS");
        let rss_rls = ls_rss(&sys, &r);
        assert!(
            rel(rss_rls, ols.rss) < 1e-6,
            "{s:?}: {rss_rls} vs {}",
            ols.rss
        );
    }
    // In Table 1 the RLS column equals the OLS reference.
    let c = comparison(&data, Record::AMultistep, Criterion::Aic, Offset::None).unwrap();
    let rmse = |m: MethodKind| &c.estimate(m).unwrap().rmse;
    for (x, y) in rmse(MethodKind::Rls).iter().zip(rmse(MethodKind::Ols)) {
        assert!(rel(x.free_run, y.free_run) < 1e-4 && rel(x.one_step, y.one_step) < 1e-4);
    }
}

/// RSS of a model on the normal equations of `sys` (same structure).
fn ls_rss(sys: &ridge_core::System<f64>, m: &ArxModel<f64>) -> f64 {
    let s = sys.structure();
    let w: Vec<f64> = (0..sys.params())
        .map(|i| match sys.regressor(i).unwrap() {
            ridge_core::Regressor::Output(k) => m.theta()[usize::from(k) - 1],
            ridge_core::Regressor::Input(k) => m.phi()[usize::from(k - s.d)],
            ridge_core::Regressor::Constant => m.intercept(),
        })
        .collect();
    sys.factor(0.0).unwrap().rss(&w)
}

#[test]
fn table_one_estimators_agree_with_the_theory_of_each() {
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    for c in [Criterion::Paper, Criterion::Aic] {
        let t = comparison(&data, Record::AMultistep, c, Offset::None).unwrap();
        let avg = |a: MethodKind| t.estimate(a).unwrap().average();
        // One-step: least squares minimises the identification record's one-step error.
        let ident = |a: MethodKind| t.estimate(a).unwrap().rmse[0].one_step;
        for a in COMPARED {
            assert!(
                ident(MethodKind::Ols) <= ident(a) * (1.0 + 1e-9),
                "{c:?} {a:?}"
            );
        }
        // Plain Ridge at γ = 1000 shrinks the input coefficients (Σu² ≈ 1e3 per column):
        // clearly worse free-run than the others.
        for a in [
            MethodKind::Rls,
            MethodKind::AdaptiveLasso,
            MethodKind::RidgeM,
        ] {
            assert!(
                avg(MethodKind::Ridge).free_run > 1.3 * avg(a).free_run,
                "{c:?} {a:?}"
            );
        }
        // A proportional model's static gain is below the plant's secant slope (the map
        // does not pass through the origin) but of the right size.
        for e in &t.estimates {
            let g = e.model.static_gain();
            assert!((100.0..160.0).contains(&g), "{c:?} {:?} gain {g}", e.method);
        }
    }
    // With an intercept the static gain of the least-squares-like estimators is the secant
    // slope of the plant's steady-state map over the record's duty range (20–90 %), and the
    // free-run error drops several-fold (dead zone → affine map).
    let pump = PumpParams::default();
    let secant = (pump.steady_state_flow(0.9) - pump.steady_state_flow(0.2)) / 0.7;
    let with = comparison(&data, Record::AMultistep, Criterion::Aic, Offset::Intercept).unwrap();
    for a in [
        MethodKind::Rls,
        MethodKind::AdaptiveLasso,
        MethodKind::RidgeM,
        MethodKind::Ols,
    ] {
        let g = with.estimate(a).unwrap().model.static_gain();
        assert!(rel(g, secant) < 0.1, "{a:?}: gain {g} vs secant {secant}");
    }
    let without = comparison(&data, Record::AMultistep, Criterion::Aic, Offset::None).unwrap();
    let ridge_m = |c: &Comparison| c.estimate(MethodKind::RidgeM).unwrap().average().free_run;
    assert!(ridge_m(&with) * 2.0 < ridge_m(&without));
}

#[test]
fn pruned_search_matches_exhaustive_with_fewer_solves_and_f32_agrees() {
    let data = Dataset::simulate(DEFAULT_SEED).unwrap();
    for c in [Criterion::Paper, Criterion::Aic] {
        for o in [Offset::None, Offset::Intercept] {
            let p = pruning(&data, Record::AMultistep, c, o).unwrap();
            assert_eq!(p.pruned, p.exhaustive, "{c:?} {o:?}");
            assert!(p.same_score);
            assert_eq!(p.candidates, 252);
            assert!(p.evaluated < 50, "{c:?} {o:?}: {}", p.evaluated);
        }
        let pr = precision(&data, Record::AMultistep, c).unwrap();
        assert_eq!(pr.structure_f32, pr.structure_f64, "{c:?}");
        assert!(pr.max_coef_diff < 1e-3 * pr.max_coef, "{c:?}: {pr:?}");
        assert!(rel(pr.free_run.1, pr.free_run.0) < 1e-3, "{c:?}: {pr:?}");
    }
}

#[test]
fn binary_prints_markdown_and_honours_flags() {
    let dir = std::env::temp_dir().join(format!("paper-tables-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("tables.md");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_paper-tables"))
        .args(["--seed", "7", "--markdown-out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8(run.stdout).unwrap();
    let file = std::fs::read_to_string(&out).unwrap();
    assert_eq!(stdout, file);
    assert!(stdout.contains("(seed 7)"));
    for needle in [
        "### Table 1",
        "### Table 2",
        "### Table 3",
        "### Table 4",
        "### Table 5",
        "Free-run RMSE",
        "One-step RMSE",
        "seeded with",
    ] {
        assert!(stdout.contains(needle), "missing {needle}");
    }
    // Usage errors: exit status 2 (clap's convention), nothing on standard output.
    for args in [&["--seed", "x"][..], &["--seed"], &["--no-such-flag"]] {
        let bad = std::process::Command::new(env!("CARGO_BIN_EXE_paper-tables"))
            .args(args)
            .output()
            .unwrap();
        assert_eq!(bad.status.code(), Some(2), "{args:?}");
        assert!(bad.stdout.is_empty(), "{args:?}");
    }
    // `--seed=N` is the same flag; `--help` lists both options and succeeds.
    let eq = std::process::Command::new(env!("CARGO_BIN_EXE_paper-tables"))
        .arg("--seed=7")
        .output()
        .unwrap();
    assert!(eq.status.success());
    assert_eq!(String::from_utf8(eq.stdout).unwrap(), stdout);
    let help = std::process::Command::new(env!("CARGO_BIN_EXE_paper-tables"))
        .arg("--help")
        .output()
        .unwrap();
    assert!(help.status.success());
    let help = String::from_utf8(help.stdout).unwrap();
    assert!(
        help.contains("--seed") && help.contains("--markdown-out"),
        "{help}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
