//! Deterministic, seedable simulation of the ridge-pump rig: excitation generator
//! (`ridge_core::excitation`) → nonlinear BLDC blower ([`pump`]) → SFM3300 sensor ([`sfm3300`]),
//! sampled at 100 Hz; plus a linear ARX simulator for known-plant tests ([`arx`]).
//!
//! # Sample convention
//! Sample `t` of a [`Log`] carries `u_t`, the duty applied during the interval that *ends* at
//! the flow measurement `y_t`, and `y_t`, that measurement. A plant with a transport delay of
//! `k` samples therefore first responds to a duty change at `u_t` in `y_{t+k}`: its ARX delay
//! is `d = k` (with `k = 0`, `φ_0` multiplies the same-sample input). Samples before `t = 0` are
//! zero duty with the pump at rest, matching the zero history of the paper's Algorithm 1.
//!
//! Randomness lives only in the sensor noise, from a xoshiro256++ stream seeded by the `seed`
//! argument: the same seed gives bit-identical logs.

pub mod arx;
pub mod baseline;
pub mod iso;
pub mod lung;
pub mod paper;
pub mod plant;
pub mod powerup;
pub mod pump;
pub mod reid;
pub mod sfm3300;
pub mod vent_bench;

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, SAMPLE_RATE_HZ};

pub use arx::simulate_arx;
pub use lung::{Lung, LungParams, Valve};
pub use plant::{Blower, Outlet, PlantArgs};
pub use pump::{Pump, PumpParams};
pub use sfm3300::{Sfm3300, Sfm3300Params};

/// Sample period of the rig, seconds (1 / [`SAMPLE_RATE_HZ`]).
pub const TS_S: f64 = 1.0 / SAMPLE_RATE_HZ as f64;

/// Duty counts (units of 1/[`DUTY_FULL_SCALE`]) → duty fraction 0..1.
pub fn duty_to_f64(duty: u16) -> f64 {
    f64::from(duty) / f64::from(DUTY_FULL_SCALE)
}

/// One recorded experiment. All vectors have the same length; index `t` is time `t·ts_s`.
#[derive(Clone, Debug, PartialEq)]
pub struct Log {
    /// Sample period, seconds.
    pub ts_s: f64,
    /// Duty applied during the interval ending at sample `t`, fraction 0..1 (`raw_u / 10000`).
    pub u: Vec<f64>,
    /// Flow measured at the end of that interval, slm, decoded from the sensor word
    /// (`(raw_y − 32768) / 120`).
    pub y: Vec<f64>,
    /// Duty as commanded, units of 1/[`DUTY_FULL_SCALE`].
    pub raw_u: Vec<u16>,
    /// SFM3300 raw words.
    pub raw_y: Vec<u16>,
}

impl Log {
    /// An empty log with sample period `ts_s`.
    pub fn new(ts_s: f64) -> Self {
        Self {
            ts_s,
            u: Vec::new(),
            y: Vec::new(),
            raw_u: Vec::new(),
            raw_y: Vec::new(),
        }
    }

    /// Appends one sample (duty counts, sensor word).
    pub fn push(&mut self, raw_u: u16, raw_y: u16) {
        self.raw_u.push(raw_u);
        self.raw_y.push(raw_y);
        self.u.push(duty_to_f64(raw_u));
        self.y.push(sfm3300::raw_to_flow(raw_y));
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// Whether the log has no samples.
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }

    /// Time of sample `t`, seconds.
    pub fn t(&self, t: usize) -> f64 {
        t as f64 * self.ts_s
    }

    /// Writes the log as CSV with header `t,u,y`: `t` in seconds, `u` the duty 0..1, `y` the
    /// flow in slm (shortest exact decimal of the decoded sensor word).
    pub fn write_csv_to<W: Write>(&self, mut w: W) -> io::Result<()> {
        writeln!(w, "t,u,y")?;
        for (i, (u, y)) in self.u.iter().zip(&self.y).enumerate() {
            writeln!(w, "{:.2},{},{}", self.t(i), u, y)?;
        }
        w.flush()
    }

    /// Writes the log as CSV (see [`Log::write_csv_to`]) to the file at `path`.
    pub fn write_csv(&self, path: impl AsRef<Path>) -> io::Result<()> {
        self.write_csv_to(BufWriter::new(File::create(path)?))
    }
}

/// The rig: a pump, optionally a test lung behind it, and a sensor, stepped once per sample.
#[derive(Clone, Debug)]
pub struct Rig {
    /// The blower (public for fault injection, e.g. `rig.pump.set_stalled(true)`).
    pub pump: Pump,
    /// The test lung, or `None` for an open outlet.
    pub lung: Option<Lung>,
    /// The flow sensor.
    pub sensor: Sfm3300,
    /// The exhalation valve the firmware drives (open unless set: the passive valve).
    pub valve: Valve,
}

impl Rig {
    /// A rig at rest with pump `pump`, an open outlet, sensor error model `sensor` and noise
    /// seed `seed`.
    pub fn new(pump: PumpParams, sensor: Sfm3300Params, seed: u64) -> Self {
        Self {
            pump: Pump::new(pump),
            lung: None,
            sensor: Sfm3300::new(sensor, seed),
            valve: Valve::Open,
        }
    }

    /// The same rig with a relaxed test lung `lung` behind the blower.
    pub fn with_lung(mut self, lung: LungParams) -> Self {
        self.lung = Some(Lung::new(lung));
        self
    }

    /// Applies `duty` (units of 1/[`DUTY_FULL_SCALE`], clamped to full scale) for one sample
    /// period and returns the sensor word measured at its end.
    pub fn step(&mut self, duty: u16) -> u16 {
        let flow = self.true_flow(duty);
        self.sensor.measure_raw(flow)
    }

    /// Applies `duty` for one sample period and returns the true flow at its end, slm: the
    /// blower's open-outlet flow, or with a lung the flow against its back pressure.
    pub fn true_flow(&mut self, duty: u16) -> f64 {
        self.flow_at(duty_to_f64(duty.min(DUTY_FULL_SCALE)))
    }

    /// As [`true_flow`](Rig::true_flow) with the duty as an unrounded fraction of full scale
    /// (0..1; the pump clamps it): the plant as a smooth function of its input, for
    /// optimisations that differentiate it numerically.
    pub fn flow_at(&mut self, duty: f64) -> f64 {
        let open = self.pump.step(duty);
        match &mut self.lung {
            Some(lung) => {
                let p = self.pump.params();
                let shutoff = p.shutoff_of_speed(self.pump.speed());
                lung.step(self.valve, open, shutoff, p.ts_s)
            }
            None => open,
        }
    }

    /// Runs a whole duty sequence (e.g. an excitation generator) and logs it.
    pub fn run<I: IntoIterator<Item = u16>>(&mut self, duties: I) -> Log {
        let mut log = Log::new(self.pump.params().ts_s);
        for d in duties {
            let d = d.min(DUTY_FULL_SCALE);
            let raw = self.step(d);
            log.push(d, raw);
        }
        log
    }
}

/// Records one preset excitation on a pump with `params` and the default SFM3300 error model,
/// sensor noise seeded by `seed`, starting from rest.
pub fn record(record: Record, params: &PumpParams, seed: u64) -> Log {
    record_with(record, params, &Sfm3300Params::default(), seed)
}

/// As [`record`] with an explicit sensor error model.
pub fn record_with(record: Record, params: &PumpParams, sensor: &Sfm3300Params, seed: u64) -> Log {
    Rig::new(params.clone(), sensor.clone(), seed).run(record.generator())
}
