//! ridge-core on a Cortex-M4F (QEMU `mps2-an386`): f32 on the FPU target, f64 in
//! software, checked against truth computed here (known plant, dense f64 reference).
//!
//! `harness = false`: the `#[entry]` runs [`TESTS`], prints `test <name> ... ok|FAILED`
//! for each, then `N passed, M failed` as its last line, and exits through semihosting
//! with a non-zero status if anything failed. Benchmarks print `BENCH <name> instr=<n>`
//! lines (instructions under QEMU `-icount shift=6`; see `qemu_tests::clock`).
#![no_std]
#![no_main]
#![allow(clippy::needless_range_loop)]

use core::hint::black_box;
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use qemu_tests::{clock, dense, rel, Plant, Record, N};
use ridge_core::{
    Error, Estimator, FloatGram, IntGram, Method, Normal, Offset, Ols, Real, Regressor, Ridge,
    RidgeM, Scale, Search, Selection, Structure,
};

/// A failed check; the details were printed where it happened.
struct Failed;
type Outcome = Result<(), Failed>;

/// Fails the test (with its line and a message) unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $($arg:tt)+) => {
        // NaN comparisons are false, so a NaN fails the check.
        let ok: bool = $cond;
        if !ok {
            hprintln!("    FAIL (line {}): {}", line!(), format_args!($($arg)+));
            return Err(Failed);
        }
    };
}

/// Unwraps a `Result`, failing the test with the error otherwise.
macro_rules! must {
    ($e:expr) => {
        match $e {
            Ok(v) => v,
            Err(err) => {
                hprintln!(
                    "    FAIL (line {}): {} -> {:?}",
                    line!(),
                    stringify!($e),
                    err
                );
                return Err(Failed);
            }
        }
    };
}

use ridge_pump_firmware::units::SCALE;
const SEED: u32 = 0x5EED_0223;

/// Shared by all tests: one 3000-sample record of the known plant and its statistics.
struct Ctx {
    plant: Plant,
    rec: Record,
    gram: IntGram,
}

fn gram_of(rec: &Record) -> Result<IntGram, Error> {
    let mut g = IntGram::new();
    for (&u, &y) in rec.u.iter().zip(rec.y.iter()) {
        g.push(u, y)?;
    }
    Ok(g)
}

fn s(p: u8, q: u8, d: u8) -> Structure {
    Structure { p, q, d }
}

/// Coefficients in ARX order `[θ₁ … θ_p, φ₀ … φ_{q-1}]` as f64, and their count.
fn coefficients<T: Real>(sel_fit: &ridge_core::Fit<T>) -> ([f64; dense::MAX], usize) {
    let m = sel_fit.model();
    let mut w = [0.0; dense::MAX];
    let mut n = 0;
    for &v in m.theta().iter().chain(m.phi().iter()) {
        w[n] = v.to_f64();
        n += 1;
    }
    (w, n)
}

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let mut m: f64 = 0.0;
    for (x, y) in a.iter().zip(b) {
        m = m.max(rel(*x, *y));
    }
    m
}

/// `true` when two selections agree bit for bit (structure, score, RSS, coefficients,
/// iterations).
fn same_bits<T: Real>(a: &Selection<T>, b: &Selection<T>) -> bool {
    let (wa, na) = coefficients(&a.fit);
    let (wb, nb) = coefficients(&b.fit);
    a.structure() == b.structure()
        && na == nb
        && wa[..na]
            .iter()
            .zip(&wb[..nb])
            .all(|(x, y)| x.to_bits() == y.to_bits())
        && a.score.to_f64().to_bits() == b.score.to_f64().to_bits()
        && a.fit.rss.to_f64().to_bits() == b.fit.rss.to_f64().to_bits()
        && a.fit.iterations == b.fit.iterations
}

/// Ridge-M (eq. 9–12) iterated on the dense f64 reference: `A = XᵀX + γI` solved by
/// Gaussian elimination each iterate, same stopping rule. Returns `(w, iterations)`.
fn ridge_m_dense(
    nrm: &dense::Normal,
    gamma: f64,
    beta: f64,
    tol: f64,
    max_iter: u32,
) -> Option<([f64; dense::MAX], u32)> {
    let n = nrm.n;
    let mut v = [0.0; dense::MAX];
    let mut w_prev = [0.0; dense::MAX];
    let mut rhs = nrm.clone();
    for k in 1..=max_iter {
        for i in 0..n {
            rhs.a[i][n] = nrm.a[i][n] + gamma * v[i];
        }
        let w = rhs.solve(gamma)?;
        let mut step = 0.0;
        for i in 0..n {
            step += (w[i] - w_prev[i]) * (w[i] - w_prev[i]);
            v[i] = beta * v[i] + (1.0 - beta) * w[i];
        }
        if libm_sqrt(step) < tol {
            return Some((w, k));
        }
        w_prev = w;
    }
    Some((w_prev, max_iter))
}

fn libm_sqrt(x: f64) -> f64 {
    Real::sqrt(x)
}

// ------------------------------------------------------------------------ tests

/// Test 1: The default f32 search finds the known plant's (2,2,3) and its coefficients.
fn known_plant_f32(c: &Ctx) -> Outcome {
    let normal = must!(c.gram.normal::<f32>(SCALE));
    let sel = must!(Search::<f32>::default().run(&normal, None));
    let (w, n) = coefficients(&sel.fit);
    let st = sel.structure();
    hprintln!(
        "    picked ({},{},{}) score {} after {} Ridge-M iterates, {}/{} candidates evaluated, {} skipped",
        st.p, st.q, st.d, sel.score, sel.fit.iterations, sel.evaluated, sel.candidates, sel.skipped
    );
    hprintln!("    theta {:?} phi {:?}", &w[..2], &w[2..n]);
    ensure!(st == s(2, 2, 3), "expected (2,2,3), got {:?}", st);

    let p = c.plant;
    let truth = [
        f64::from(p.theta[0]),
        f64::from(p.theta[1]),
        f64::from(p.phi[0]),
        f64::from(p.phi[1]),
    ];
    let d_theta = (w[0] - truth[0]).abs().max((w[1] - truth[1]).abs());
    let r_phi = rel(w[2], truth[2]).max(rel(w[3], truth[3]));
    hprintln!(
        "    vs truth {:?}: max |dtheta| {:e}, max rel dphi {:e}",
        truth,
        d_theta,
        r_phi
    );
    ensure!(d_theta < 0.01, "|dtheta| {} >= 0.01", d_theta);
    ensure!(r_phi < 0.02, "rel dphi {} >= 2 %", r_phi);

    // The data's own answer: Ridge-M iterated on the brute-force f64 normal equations.
    let reference = dense::Normal::of(&c.rec, 2, 2, 3);
    let rm = RidgeM::<f64>::default();
    let (wd, kd) = match ridge_m_dense(&reference, rm.gamma, rm.beta, rm.tol, rm.max_iter) {
        Some(x) => x,
        None => {
            ensure!(false, "dense reference singular");
            unreachable!()
        }
    };
    let r = max_rel(&w[..4], &wd[..4]);
    hprintln!(
        "    vs dense f64 Ridge-M ({} iterates): max rel {:e}",
        kd,
        r
    );
    ensure!(r < 1e-3, "f32 Ridge-M vs dense f64 Ridge-M: rel {}", r);
    if let Some(ols) = reference.solve(0.0) {
        hprintln!("    dense f64 OLS (2,2,3): {:?}", &ols[..4]);
    }
    // RSS of the f32 fit vs the RSS of its coefficients summed row by row.
    let rss = dense::rss(&c.rec, 2, 2, 3, &w[..4]);
    let r = rel(sel.fit.rss.to_f64(), rss);
    hprintln!(
        "    RSS {} slm^2 (row by row {}), rel {:e}",
        sel.fit.rss,
        rss,
        r
    );
    ensure!(r < 1e-3, "RSS rel {}", r);
    Ok(())
}

/// Further records: heavy noise (±400 counts, 3.3 slm) and a delay-free low-noise plant.
const VARIANTS: [(&str, Plant, u32); 2] = [
    (
        "record B (noise 400)",
        Plant {
            noise: 400,
            ..Plant::PUMP_223
        },
        7,
    ),
    (
        "record C (d=0, noise 5)",
        Plant {
            d: 0,
            noise: 5,
            ..Plant::PUMP_223
        },
        8,
    ),
];

/// Test 2: f32 (FPU) and f64 (software) on the same exact statistics.
fn f32_vs_f64(c: &Ctx) -> Outcome {
    let search = |label: &str, gram: &IntGram| -> Outcome {
        let n32 = must!(gram.normal::<f32>(SCALE));
        let n64 = must!(gram.normal::<f64>(SCALE));
        let a = must!(Search::<f32>::default().run(&n32, None));
        let b = must!(Search::<f64>::default().run(&n64, None));
        let (wa, na) = coefficients(&a.fit);
        let (wb, _) = coefficients(&b.fit);
        let coef = max_rel(&wa[..na], &wb[..na]);
        let rss = rel(a.fit.rss.to_f64(), b.fit.rss);
        let score = (a.score.to_f64() - b.score).abs();
        let st = a.structure();
        // The RSS is the last pivot of a Cholesky of what y_{t-1} leaves of yᵀy
        // (`schur`), so f32 resolves it to about ε₃₂ · schur / RSS, relative.
        let sys = must!(n64.system(st, Offset::None));
        let k = sys.params();
        let schur =
            sys.augmented(k, k) - sys.augmented(0, k) * sys.augmented(0, k) / sys.augmented(0, 0);
        let predicted = f64::from(f32::EPSILON) * schur / b.fit.rss;
        hprintln!(
            "    F32F64 {} structure=({},{},{}) coef_maxrel={:e} rss_rel={:e} eps_schur_over_rss={:e} score_absdiff={:e}",
            label, st.p, st.q, st.d, coef, rss, predicted, score
        );
        ensure!(
            a.structure() == b.structure(),
            "{}: f32 picked {:?}, f64 {:?}",
            label,
            a.structure(),
            b.structure()
        );
        ensure!(coef < 1e-3, "{}: coefficients differ by {}", label, coef);
        ensure!(
            rss < 4.0 * predicted,
            "{}: RSS differs by {} (> 4 ε schur/RSS = {})",
            label,
            rss,
            4.0 * predicted
        );
        Ok(())
    };
    search("record A", &c.gram)?;
    for (label, plant, seed) in VARIANTS {
        let rec = Record::simulate(&plant, seed);
        search(label, &must!(gram_of(&rec)))?;
    }

    // Every candidate of record A: least-squares RSS (the pruning bound), its AIC
    // term N ln(RSS/N), and the OLS coefficients.
    let n32 = must!(c.gram.normal::<f32>(SCALE));
    let n64 = must!(c.gram.normal::<f64>(SCALE));
    let (mut worst_rss, mut worst_coef): (f64, f64) = (0.0, 0.0);
    let (mut rss_at, mut coef_at) = (s(1, 1, 0), s(1, 1, 0));
    let mut fitted = 0u32;
    for st in ridge_core::Grid::default().iter() {
        let (Ok(s32), Ok(s64)) = (n32.system(st, Offset::None), n64.system(st, Offset::None))
        else {
            continue;
        };
        let (Ok(f32_), Ok(f64_)) = (Ols.fit(&s32), Ols.fit(&s64)) else {
            continue;
        };
        fitted += 1;
        let (x, n) = coefficients(&f32_);
        let (y, _) = coefficients(&f64_);
        let r = rel(f32_.rss.to_f64(), f64_.rss);
        let cr = max_rel(&x[..n], &y[..n]);
        if r > worst_rss {
            worst_rss = r;
            rss_at = st;
        }
        if cr > worst_coef {
            worst_coef = cr;
            coef_at = st;
        }
    }
    // |N ln(RSS32/N) − N ln(RSS64/N)| ≈ N · rel for small rel.
    let aic = N as f64 * worst_rss;
    hprintln!(
        "    F32F64 ols_all candidates={} rss_maxrel={:e} at ({},{},{}) (= {:.2} AIC units) coef_maxrel={:e} at ({},{},{})",
        fitted, worst_rss, rss_at.p, rss_at.q, rss_at.d, aic, worst_coef, coef_at.p, coef_at.q, coef_at.d
    );
    ensure!(fitted > 200, "only {} candidates fitted in both", fitted);
    ensure!(worst_rss < 1e-2, "OLS RSS differs by {}", worst_rss);
    Ok(())
}

/// Test 3: Pruned search == exhaustive search, bit for bit (f32, plus one f64 record).
fn pruned_equals_exhaustive(c: &Ctx) -> Outcome {
    let check = |label: &str, normal: &Normal<f32>| -> Outcome {
        let pruned = must!(Search::<f32>::default().run(normal, None));
        let full = must!(Search {
            prune: false,
            ..Search::<f32>::default()
        }
        .run(normal, None));
        let st = pruned.structure();
        hprintln!(
            "    {}: ({},{},{}) pruned evaluated {} of {}, exhaustive {}",
            label,
            st.p,
            st.q,
            st.d,
            pruned.evaluated,
            pruned.candidates,
            full.evaluated
        );
        ensure!(same_bits(&pruned, &full), "{}: pruned != exhaustive", label);
        Ok(())
    };
    check("record A", &must!(c.gram.normal::<f32>(SCALE)))?;
    for (label, plant, seed) in VARIANTS {
        let rec = Record::simulate(&plant, seed);
        let g = must!(gram_of(&rec));
        check(label, &must!(g.normal::<f32>(SCALE)))?;
    }
    let n64 = must!(c.gram.normal::<f64>(SCALE));
    let pruned = must!(Search::<f64>::default().run(&n64, None));
    let full = must!(Search {
        prune: false,
        ..Search::<f64>::default()
    }
    .run(&n64, None));
    hprintln!(
        "    f64 record A: pruned evaluated {} of {}",
        pruned.evaluated,
        pruned.candidates
    );
    ensure!(same_bits(&pruned, &full), "f64: pruned != exhaustive");
    Ok(())
}

/// Test 4: Bad data gives the documented errors.
fn bad_data(_: &Ctx) -> Outcome {
    // NaN (and ±∞) into FloatGram::push: NonFinite, statistics unchanged.
    let mut g = FloatGram::new();
    must!(g.push(0.5, 20.0));
    let before = g.clone();
    for (u, y) in [(f64::NAN, 1.0), (0.5, f64::NAN), (f64::INFINITY, 1.0)] {
        ensure!(
            g.push(u, y) == Err(Error::NonFinite),
            "push({}, {}) accepted",
            u,
            y
        );
    }
    ensure!(g == before, "statistics changed by a rejected sample");

    // Constant input: NotExcited (integer and float statistics).
    let mut rng = qemu_tests::Rng::new(3);
    let mut gi = IntGram::new();
    let mut gf = FloatGram::new();
    for _ in 0..500 {
        let y = rng.range(1000, 5000);
        must!(gi.push(5000, y));
        must!(gf.push(0.5, f64::from(y) / 120.0));
    }
    ensure!(
        gi.normal::<f32>(SCALE).err() == Some(Error::NotExcited),
        "constant input (int): {:?}",
        gi.normal::<f32>(SCALE).err()
    );
    ensure!(
        gf.normal::<f32>(Scale::UNIT).err() == Some(Error::NotExcited),
        "constant input (float): {:?}",
        gf.normal::<f32>(Scale::UNIT).err()
    );

    // A 2-sample record: the statistics form, but no candidate fits.
    let mut g2 = IntGram::new();
    must!(g2.push(3000, 100));
    must!(g2.push(7000, 900));
    let n2 = must!(g2.normal::<f32>(SCALE));
    let r = Search::<f32>::default().run(&n2, None);
    ensure!(
        r.as_ref().err() == Some(&Error::NoCandidate),
        "2 samples: {:?}",
        r.map(|s| s.structure())
    );
    Ok(())
}

/// Test 5: The first Ridge-M iterate is plain Ridge (bit for bit), and Ridge matches
/// the dense reference.
fn ridge_first_iterate(c: &Ctx) -> Outcome {
    let n32 = must!(c.gram.normal::<f32>(SCALE));
    let n64 = must!(c.gram.normal::<f64>(SCALE));
    for (p, q, d) in [(2u8, 2u8, 3u8), (6, 6, 0), (3, 4, 2)] {
        let st = s(p, q, d);
        let reference = dense::Normal::of(&c.rec, p.into(), q.into(), d.into());
        for gamma in [1000.0, 1.0] {
            let wd = match reference.solve(gamma) {
                Some(w) => w,
                None => {
                    ensure!(false, "dense reference singular");
                    unreachable!()
                }
            };
            let sys32 = must!(n32.system(st, Offset::None));
            let sys64 = must!(n64.system(st, Offset::None));
            let g32 = gamma as f32;
            let ridge32 = must!(Ridge { gamma: g32 }.fit(&sys32));
            let first32 = must!(RidgeM {
                gamma: g32,
                max_iter: 1,
                ..RidgeM::default()
            }
            .fit(&sys32));
            let ridge64 = must!(Ridge { gamma }.fit(&sys64));
            let first64 = must!(RidgeM {
                gamma,
                max_iter: 1,
                ..RidgeM::default()
            }
            .fit(&sys64));
            let (a, n) = coefficients(&ridge32);
            let (b, _) = coefficients(&first32);
            let (x, _) = coefficients(&ridge64);
            let (y, _) = coefficients(&first64);
            let bits =
                |u: &[f64], v: &[f64]| u.iter().zip(v).all(|(i, j)| i.to_bits() == j.to_bits());
            ensure!(
                bits(&a[..n], &b[..n]),
                "f32 ({p},{q},{d}) γ={gamma}: RidgeM[1] != Ridge"
            );
            ensure!(
                bits(&x[..n], &y[..n]),
                "f64 ({p},{q},{d}) γ={gamma}: RidgeM[1] != Ridge"
            );
            // The first visited iterate of a default run is the Ridge solution too.
            let mut first = [0.0f32; 13];
            must!(RidgeM {
                gamma: g32,
                ..RidgeM::default()
            }
            .iterate(&sys32, |k, w| if k == 1 {
                first[..w.len()].copy_from_slice(w)
            }));
            // Visited iterates are in internal order: map them to ARX order.
            let mut first_arx = [0.0f64; dense::MAX];
            for (i, &v) in first.iter().enumerate().take(n) {
                let j = match sys32.regressor(i) {
                    Some(Regressor::Output(k)) => usize::from(k) - 1,
                    Some(Regressor::Input(k)) => usize::from(p) + usize::from(k - d),
                    other => {
                        ensure!(false, "unexpected regressor {:?}", other);
                        unreachable!()
                    }
                };
                first_arx[j] = f64::from(v);
            }
            ensure!(
                bits(&first_arx[..n], &a[..n]),
                "f32 ({p},{q},{d}) γ={gamma}: visited iterate 1 != Ridge"
            );
            let e64 = max_rel(&x[..n], &wd[..n]);
            let e32 = max_rel(&a[..n], &wd[..n]);
            hprintln!(
                "    ({},{},{}) gamma={}: Ridge vs dense f64: f64 rel {:e}, f32 rel {:e}",
                p,
                q,
                d,
                gamma,
                e64,
                e32
            );
            // The dense reference solves the raw XᵀX (condition up to ~1e8 for the
            // 12-parameter case at γ = 1), so agreement is limited to about κ·ε₆₄.
            ensure!(e64 < 1e-6, "f64 Ridge vs dense: {}", e64);
            // Loose for the 12-parameter, ill-conditioned case at γ = 1.
            ensure!(e32 < 5e-2, "f32 Ridge vs dense: {}", e32);
        }
    }
    Ok(())
}

/// The SysTick/icount instruction formula, checked against a loop of known length.
fn icount_calibration(_: &Ctx) -> Outcome {
    let (n1, n2) = (10_000u32, 1_010_000u32);
    let (a, b) = clock::calibrate(n1, n2);
    let expected = 2 * u64::from(n2 - n1);
    let got = clock::instructions(b - a);
    hprintln!(
        "    spin({}) {} ticks, spin({}) {} ticks: {} instructions for {} expected (ticks*40/64)",
        n1,
        a,
        n2,
        b,
        got,
        expected
    );
    // Allowance: one tick of rounding at each end, plus one SysTick wrap handler
    // (~16 instructions) that may run inside a measurement.
    ensure!(
        got.abs_diff(expected) <= 40,
        "instructions = ticks*40/64 does not hold: is QEMU running with -icount shift=6?"
    );
    Ok(())
}

/// Test 6: Instruction counts (QEMU `-icount shift=6`, opt-level "s", LTO).
fn bench(c: &Ctx) -> Outcome {
    let instr = clock::instructions;

    let mut g = IntGram::new();
    let (t, r) = clock::measure(|| {
        for (&u, &y) in c.rec.u.iter().zip(c.rec.y.iter()) {
            if g.push(black_box(u), black_box(y)).is_err() {
                return false;
            }
        }
        true
    });
    ensure!(r && g == c.gram, "push loop");
    hprintln!("BENCH push instr={} samples={}", instr(t) / N as u64, N);

    let mut g1 = black_box(c.gram.clone());
    let (t, r) = clock::measure(|| g1.push(black_box(5000), black_box(4800)));
    must!(r);
    hprintln!("BENCH push_single instr={}", instr(t));

    let (t, n32) = clock::measure(|| black_box(&c.gram).normal::<f32>(SCALE));
    let n32 = must!(n32);
    hprintln!("BENCH normal_f32 instr={}", instr(t));
    let (t, n64) = clock::measure(|| black_box(&c.gram).normal::<f64>(SCALE));
    let n64 = must!(n64);
    hprintln!("BENCH normal_f64 instr={}", instr(t));

    let st = s(6, 6, 0);
    let sys32 = must!(n32.system(st, Offset::None));
    let sys64 = must!(n64.system(st, Offset::None));
    let (t, f) = clock::measure(|| black_box(&sys32).factor(black_box(1000.0f32)));
    let f = must!(f);
    ensure!(f.params() == 12, "params {}", f.params());
    hprintln!("BENCH factor12_f32 instr={}", instr(t));
    let (t, w) = clock::measure(|| black_box(&f).solution());
    black_box(w);
    hprintln!("BENCH solution12_f32 instr={}", instr(t));
    let (t, f) = clock::measure(|| black_box(&sys64).factor(black_box(1000.0f64)));
    must!(f);
    hprintln!("BENCH factor12_f64 instr={}", instr(t));

    let (t, sel) = clock::measure(|| Search::<f32>::default().run(black_box(&n32), None));
    let sel = must!(sel);
    ensure!(
        sel.structure() == s(2, 2, 3),
        "search picked {:?}",
        sel.structure()
    );
    hprintln!(
        "BENCH search_f32 instr={} evaluated={} candidates={}",
        instr(t),
        sel.evaluated,
        sel.candidates
    );
    let (t, sel) = clock::measure(|| {
        Search::<f32> {
            prune: false,
            ..Search::default()
        }
        .run(black_box(&n32), None)
    });
    let sel = must!(sel);
    hprintln!(
        "BENCH search_f32_exhaustive instr={} evaluated={}",
        instr(t),
        sel.evaluated
    );
    let (t, sel) = clock::measure(|| Search::<f64>::default().run(black_box(&n64), None));
    let sel = must!(sel);
    hprintln!(
        "BENCH search_f64 instr={} evaluated={}",
        instr(t),
        sel.evaluated
    );
    let (t, sel) = clock::measure(|| {
        Search::<f32> {
            method: Method::Ols,
            ..Search::default()
        }
        .run(black_box(&n32), None)
    });
    let sel = must!(sel);
    hprintln!(
        "BENCH search_f32_ols instr={} evaluated={}",
        instr(t),
        sel.evaluated
    );

    // ridge-core's f32 square root is libm::sqrtf: software even with an FPU.
    let (t, r) = clock::measure(|| Real::sqrt(black_box(2.0f32)));
    black_box(r);
    hprintln!("BENCH sqrtf_libm instr={}", instr(t));
    let (t, r) = clock::measure(|| vsqrt(black_box(2.0f32)));
    black_box(r);
    hprintln!("BENCH sqrtf_vsqrt instr={}", instr(t));
    Ok(())
}

// The FPU's square root (`vsqrt.f32`), for comparison with libm's software one. Hard-float ABI: the
// argument and the result are in s0. `asm!` cannot name FPU registers here (the
// register class wants a `vfp2` target feature), a global_asm! function can.
core::arch::global_asm!(
    ".section .text.qemu_tests_vsqrt, \"ax\", %progbits",
    ".global qemu_tests_vsqrt",
    ".type qemu_tests_vsqrt, %function",
    ".thumb_func",
    "qemu_tests_vsqrt:",
    "vsqrt.f32 s0, s0",
    "bx lr",
);
extern "C" {
    fn qemu_tests_vsqrt(x: f32) -> f32;
}

fn vsqrt(x: f32) -> f32 {
    // SAFETY: the routine above touches only s0 and returns.
    unsafe { qemu_tests_vsqrt(x) }
}

type Test = (&'static str, fn(&Ctx) -> Outcome);

const TESTS: &[Test] = &[
    ("known_plant_f32", known_plant_f32),
    ("f32_vs_f64", f32_vs_f64),
    ("pruned_equals_exhaustive", pruned_equals_exhaustive),
    ("bad_data", bad_data),
    ("ridge_first_iterate", ridge_first_iterate),
    ("icount_calibration", icount_calibration),
    ("bench", bench),
];

#[entry]
fn main() -> ! {
    if let Some(mut cp) = cortex_m::Peripherals::take() {
        clock::start(&mut cp.SYST);
    }
    let plant = Plant::PUMP_223;
    let rec = Record::simulate(&plant, SEED);
    let gram = match gram_of(&rec) {
        Ok(g) => g,
        Err(e) => {
            hprintln!("setup: IntGram::push failed: {:?}", e);
            hprintln!("0 passed, {} failed", TESTS.len());
            exit(false)
        }
    };
    let ctx = Ctx { plant, rec, gram };
    hprintln!(
        "ridge-core on Cortex-M4F (QEMU mps2-an386): {} tests, record of {} samples",
        TESTS.len(),
        N
    );
    let (mut passed, mut failed) = (0u32, 0u32);
    for (name, test) in TESTS {
        hprintln!("---- {}", name);
        let t0 = clock::now();
        let r = test(&ctx);
        let dt = clock::now() - t0;
        let status = if r.is_ok() { "ok" } else { "FAILED" };
        hprintln!(
            "test {} ... {} ({} Minstr)",
            name,
            status,
            clock::instructions(dt) / 1_000_000
        );
        match r {
            Ok(()) => passed += 1,
            Err(Failed) => failed += 1,
        }
    }
    hprintln!("{} passed, {} failed", passed, failed);
    exit(failed == 0)
}

/// Ends the QEMU run with status 0 (`ok`) or 1 through semihosting.
fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Not reached under QEMU; a debugger without semihosting exit stops here.
    loop {
        cortex_m::asm::wfi();
    }
}

#[exception]
fn SysTick() {
    clock::on_wrap();
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    hprintln!("HardFault at pc {:#010x}: {:?}", ef.pc(), ef);
    hprintln!("0 passed, 1 failed");
    exit(false)
}
