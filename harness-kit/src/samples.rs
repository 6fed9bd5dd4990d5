//! A record as the firmware saw it, rebuilt from the bench's own logs.
//!
//! Sample convention (firmware `selfid`): at each tick the firmware reads `y_t` and pushes
//! `(u, y_t)` with `u` the duty applied during the interval that ends with that reading, i.e.
//! the duty it wrote in the previous tick. A bench logs every frame the simulated sensor
//! served and every duty on the pump's pin, so the pairs are rebuilt from those: the frames of
//! the record are the run of consecutive frames whose duty at the read is the record
//! generator's sequence (rebuilt from the `MAP` and `SCAN` lines and the firmware's settings),
//! checked in the board's own PWM timer counts. The model's input is the static map's flow at
//! the duty (`(v, y_t)`, `v` = map(u)).

use ridge_core::InputMap;
use ridge_pump_firmware::excitation::{FlowSteps, Record};
use ridge_pump_firmware::lines::{ExciteLine, MapLine, ScanLine, ValidateLine};
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::sfm3300::raw_to_counts;
use ridge_pump_firmware::units::SLM_PER_COUNT;

/// A record as the firmware saw it: the duty (1/10 000) in effect at each read and the raw
/// word read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Samples {
    /// The preset the duties follow (a fresh host-side record,
    /// [`crate::validation::fresh_record`]); `None` for the device's own records
    /// (`flow-steps`).
    pub record: Option<Record>,
    /// The static map the model's input goes through (the `MAP` line before the record, or
    /// the model's for a fresh record).
    pub map: Option<InputMap>,
    /// Duties, 1/10 000.
    pub u: Vec<u16>,
    /// SFM3300 raw words.
    pub raw: Vec<u16>,
    /// When each read happened, in the harness's time unit (0 for a host-made record).
    pub at: Vec<u64>,
    /// Operating point the firmware subtracts (`EXCITE … u0= y0=`): duty 1/10 000 (the map's
    /// flow there is what it subtracts from the map's flow).
    pub u0: u16,
    /// Operating point flow, counts (`raw − 32768`).
    pub y0: i16,
    /// The operating point recomputed from the served frames as the firmware defines it:
    /// rounded mean (halves away from zero) of the last 50 readings of the settle phase (the
    /// one read in the tick that printed `SCAN` the last).
    pub y0_frames: Option<i16>,
}

impl Samples {
    /// The model's input at sample `i`: the map's flow at its duty, slm (the duty as a
    /// fraction without a map).
    pub fn input(&self, i: usize) -> f64 {
        let u = self.u.get(i).copied().unwrap_or(0);
        match &self.map {
            Some(m) => f64::from(m.at(u)) * f64::from(SLM_PER_COUNT),
            None => f64::from(u) / 10_000.0,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// Whether empty.
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }
}

/// Rebuilds the record that line `idx` of `lines` announces (`EXCITE flow-steps n=.. u0=..
/// y0=..` or `VALIDATE flow-steps n=..`; `lines`: every line with when its first byte left the
/// UART) from `frames` (when each frame was served, the raw word; in time order), aligned on
/// the record generator's duty sequence: `FlowSteps` on the map of the last `MAP` line before
/// it, with the firmware's settings and the lag of the last `SCAN` line (the validation
/// record's seed is the complement of the estimation record's). `pwm_is(at, duty)`: whether
/// the pump's PWM in effect at `at` is what the board writes for `duty` (1/10 000), in its
/// timer's counts. The record starts within three frames of the line.
pub fn rebuild(
    lines: &[(u64, &str)],
    idx: usize,
    frames: &[(u64, u16)],
    pwm_is: impl Fn(u64, u16) -> bool,
) -> Option<Samples> {
    let &(line_at, text) = lines.get(idx)?;
    // (samples, operating point: duty 1/10 000, flow counts (none on VALIDATE), seed)
    let r = &DEFAULT_CONFIG.records;
    let (n, u0, y0, seed) = match ExciteLine::parse(text) {
        Ok(e) => (e.samples, e.u0, e.y0, r.seed),
        Err(_) => {
            let v = ValidateLine::parse(text).ok()?;
            (v.samples, 0, 0, !r.seed)
        }
    };
    let before = |keyword: &str| {
        lines[..idx]
            .iter()
            .rposition(|(_, t)| t.split_whitespace().next() == Some(keyword))
    };
    let map = MapLine::parse(lines[before("MAP")?].1).ok()?.map;
    let scan = before("SCAN")?;
    let lag = ScanLine::parse(lines[scan].1).ok()?.lag;
    let samples = u16::try_from(n).ok()?;
    let mut steps = FlowSteps::new(&map, &r.shape(lag, samples, seed))?;
    let gen: Vec<u16> = std::iter::from_fn(|| steps.next_step().map(|(d, _)| d)).collect();
    let j0 = frames.partition_point(|(at, _)| *at < line_at);
    for k in j0.saturating_sub(3)..=j0 + 3 {
        if k + gen.len() > frames.len() {
            break;
        }
        let ok = gen
            .iter()
            .enumerate()
            .all(|(i, &g)| pwm_is(frames[k + i].0, g));
        if ok {
            let settled = frames.partition_point(|(at, _)| *at < lines[scan].0);
            let y0_frames = (settled >= 50).then(|| {
                let sum: i32 = frames[settled - 50..settled]
                    .iter()
                    .map(|(_, raw)| i32::from(raw_to_counts(*raw)))
                    .sum();
                let half = if sum >= 0 { 25 } else { -25 };
                ((sum + half) / 50) as i16
            });
            let mut s = Samples {
                map: Some(map),
                u0,
                y0,
                y0_frames,
                ..Samples::default()
            };
            for (i, &g) in gen.iter().enumerate() {
                s.u.push(g);
                s.raw.push(frames[k + i].1);
                s.at.push(frames[k + i].0);
            }
            return Some(s);
        }
    }
    None
}
