//! Benchmarks of ridge-core on the host: one statistics update and the full default
//! structure search (252 candidates) from a 3000-sample simulated pump record.
//! `cargo bench -p host-tests --bench core`; figures are quoted in the README.
use criterion::{criterion_group, criterion_main, Criterion};
use pump_sim::{record, PumpParams};
use ridge_core::{FloatGram, IntGram, Search};
use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::SCALE;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let log = record(Record::AMultistep, &PumpParams::default(), 1);
    let samples: Vec<(i32, i32)> = log
        .raw_u
        .iter()
        .zip(&log.raw_y)
        .map(|(&u, &y)| (i32::from(u), i32::from(y) - 32768))
        .collect();

    c.bench_function("IntGram::push (one sample)", |b| {
        let mut g = IntGram::new();
        let mut i = 0usize;
        b.iter(|| {
            let (u, y) = samples[i % samples.len()];
            i += 1;
            if g.push(black_box(u), black_box(y)).is_err() {
                g = IntGram::new();
            }
        })
    });
    c.bench_function("FloatGram::push (one sample)", |b| {
        let mut g = FloatGram::new();
        let mut i = 0usize;
        b.iter(|| {
            let k = i % log.u.len();
            i += 1;
            let _ = g.push(black_box(log.u[k]), black_box(log.y[k]));
        })
    });

    let mut g = IntGram::new();
    for &(u, y) in &samples {
        g.push(u, y).unwrap();
    }
    c.bench_function("Gram::normal::<f32> (3000 samples)", |b| {
        b.iter(|| black_box(&g).normal::<f32>(SCALE).unwrap())
    });
    let n32 = g.normal::<f32>(SCALE).unwrap();
    let n64 = g.normal::<f64>(SCALE).unwrap();
    for prune in [true, false] {
        let label = if prune { "pruned" } else { "exhaustive" };
        c.bench_function(&format!("search f32 {label} (252 candidates)"), |b| {
            let s = Search::<f32> {
                prune,
                ..Search::default()
            };
            b.iter(|| s.run(black_box(&n32), None).unwrap())
        });
        c.bench_function(&format!("search f64 {label} (252 candidates)"), |b| {
            let s = Search::<f64> {
                prune,
                ..Search::default()
            };
            b.iter(|| s.run(black_box(&n64), None).unwrap())
        });
    }
    let sel = Search::<f32>::default().run(&n32, None).unwrap();
    println!(
        "pruned search evaluated {} of {} candidates, picked {:?}",
        sel.evaluated,
        sel.candidates,
        sel.structure()
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(2)).warm_up_time(std::time::Duration::from_millis(500));
    targets = bench
}
criterion_main!(benches);
