//! A model scored on a record (the firmware's validation record, or a fresh one made on the
//! host with the loop's timing), and the plot of measured vs model flow.

use std::path::Path;

use pump_sim::{Lung, LungParams, Pump, PumpParams, Sfm3300, Sfm3300Params, Valve};
use ridge_core::{ArxModel, Evaluation, InputMap};
use ridge_id::eval::Trace;
use ridge_id::plot::{write_fit_png, Axes, Panel};
use ridge_pump_firmware::excitation::Record;

use crate::samples::Samples;

/// Excitation preset of the fresh host-side validation signal (a record the firmware neither
/// estimates nor validates on).
pub const FRESH_RECORD: Record = Record::BRamp;

/// Plant sub-steps per 10 ms tick in both benches (0.5 ms each).
pub const SUBSTEPS: usize = 20;

/// What the fresh signal's sensor-noise seed adds to the run's seed (a new noise draw).
pub const FRESH_SEED_OFFSET: u64 = 1000;

/// The fresh signal's base duty, 1/10 000 (30 %: held 2 s before the record).
pub const FRESH_BASE: u16 = 3_000;

/// Write latency (0.5 ms sub-steps) when the estimation record could not be rebuilt.
pub const FRESH_LATENCY_DEFAULT: usize = 2;

/// The report's fresh validation signal for a run with noise seed `seed`: [`FRESH_RECORD`]
/// from [`FRESH_BASE`], noise seed `seed + FRESH_SEED_OFFSET`, the measured write `latency`
/// (or [`FRESH_LATENCY_DEFAULT`]), the model's `map`; `frac` as in [`fresh_record`]. Returns
/// the record and the latency used.
pub fn fresh_signal(
    pump: &PumpParams,
    lung: Option<&LungParams>,
    sensor: &Sfm3300Params,
    seed: u64,
    map: Option<InputMap>,
    latency: Option<usize>,
    frac: impl Fn(u16) -> f64,
) -> (Samples, usize) {
    let latency = latency.unwrap_or(FRESH_LATENCY_DEFAULT);
    let fresh = FreshRecord {
        pump,
        lung,
        sensor,
        seed: seed.wrapping_add(FRESH_SEED_OFFSET),
        record: FRESH_RECORD,
        map,
        base: FRESH_BASE,
        latency,
    };
    let rec = fresh_record(&fresh, frac);
    (rec, latency)
}

/// Free-run and one-step fits (%) of `model` on `samples` (physical units, the input through
/// the samples' map; ridge-core's `Evaluation`, eq. 16 of the paper), with the trace for a
/// plot.
pub fn score(model: &ArxModel<f64>, samples: &Samples) -> (Option<f64>, Option<f64>, Trace) {
    let mut ev = Evaluation::new(*model);
    let mut trace = Trace::new(samples.len() as u64, 2000);
    for (i, &raw) in samples.raw.iter().enumerate() {
        let y = pump_sim::sfm3300::raw_to_flow(raw);
        let p = ev.push(samples.input(i), y);
        trace.push(i as u64, y, p);
    }
    trace.finish();
    (
        ev.free_run().map(|m| m.fit),
        ev.one_step().map(|m| m.fit),
        trace,
    )
}

/// What a fresh validation signal is made of ([`fresh_record`]); each harness adds how its
/// board's PWM timer makes the duty.
#[derive(Clone, Copy, Debug)]
pub struct FreshRecord<'a> {
    /// The blower.
    pub pump: &'a PumpParams,
    /// The test lung, if any (its exhalation valve open, as in the identification).
    pub lung: Option<&'a LungParams>,
    /// The sensor model.
    pub sensor: &'a Sfm3300Params,
    /// The sensor-noise seed.
    pub seed: u64,
    /// The excitation preset.
    pub record: Record,
    /// The model's map, kept with the samples for scoring.
    pub map: Option<InputMap>,
    /// The duty held for 2 s before the record, 1/10 000.
    pub base: u16,
    /// Plant sub-steps (0.5 ms) from the tick's reading to the new duty.
    pub latency: usize,
}

/// A fresh validation signal on the host, with the loop's timing: the plant (blower `f.pump`,
/// test lung `f.lung` if any) sub-stepped as in the benches ([`SUBSTEPS`]), the reading taken at
/// the tick, the new duty applied `f.latency` sub-steps later as the fraction `frac(duty)` the
/// board's PWM timer makes of it, the sensor noise from `f.seed`. Starts from `f.base` duty held
/// for 2 s, as the firmware settles. `f.map`: the model's map, kept with the samples for
/// scoring.
pub fn fresh_record(f: &FreshRecord<'_>, frac: impl Fn(u16) -> f64) -> Samples {
    let FreshRecord {
        pump,
        lung,
        sensor,
        seed,
        record,
        map,
        base,
        latency,
    } = *f;
    let mut p = pump.clone();
    p.ts_s /= SUBSTEPS as f64;
    p.delay_samples *= SUBSTEPS;
    let mut pump = Pump::new(p);
    let mut lung = lung.cloned().map(Lung::new);
    let mut sfm = Sfm3300::new(sensor.clone(), seed);
    // One 0.5 ms plant step at duty `d`: the flow at its end.
    let mut step = |d: u16| {
        let open = pump.step(frac(d));
        match &mut lung {
            Some(l) => {
                let p = pump.params();
                // The firmware holds the exhalation valve open while it identifies.
                l.step(Valve::Open, open, p.shutoff_of_speed(pump.speed()), p.ts_s)
            }
            None => open,
        }
    };
    let latency = latency.min(SUBSTEPS);
    let mut prev = base;
    let mut flow = 0.0;
    for _ in 0..200 * SUBSTEPS {
        flow = step(base);
    }
    let mut s = Samples {
        record: Some(record),
        map,
        ..Samples::default()
    };
    for g in record.generator() {
        for _ in 0..latency {
            flow = step(prev);
        }
        for _ in latency..SUBSTEPS {
            flow = step(g);
        }
        prev = g;
        let raw = sfm.measure_raw(flow);
        s.u.push(g);
        s.raw.push(raw);
        s.at.push(0);
    }
    s.u0 = base;
    s
}

/// Median sub-steps between a read of `samples` and the PWM change that follows it within
/// `tick` (the duty written is seen by the plant at the next 0.5 ms step): `changes` are the
/// times the plant saw a new duty, in order, in the unit of `samples.at`. 1 without any.
pub fn write_latency(samples: &Samples, changes: &[u64], tick: u64) -> usize {
    let step = tick / SUBSTEPS as u64;
    let mut lat: Vec<u64> = samples
        .at
        .iter()
        .filter_map(|&t| {
            let i = changes.partition_point(|&c| c <= t);
            let c = *changes.get(i)?;
            (c - t < tick).then(|| (c - t).div_ceil(step))
        })
        .collect();
    if lat.is_empty() {
        return 1;
    }
    lat.sort_unstable();
    lat[lat.len() / 2] as usize
}

/// Writes a PNG with one panel per `(title, trace)`.
pub fn plot(path: &Path, panels: &[(String, Trace)]) -> Result<(), String> {
    let p: Vec<Panel<'_>> = panels
        .iter()
        .map(|(t, tr)| Panel {
            title: t.clone(),
            trace: tr,
        })
        .collect();
    write_fit_png(path, &Axes::pump(), &p).map_err(|e| e.to_string())
}
