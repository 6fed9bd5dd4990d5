//! A record as the firmware saw it, rebuilt from the bench's own logs.
//!
//! Sample convention (firmware `selfid`): at each tick the firmware reads `y_t` and pushes
//! `(u, y_t)` with `u` the duty applied during the interval that ends with that reading, i.e.
//! the duty it wrote in the previous tick. A bench logs every frame the simulated sensor
//! served and every duty on the pump's pin, so the pairs are rebuilt from those: the frames of
//! the record are the run of consecutive frames whose duty at the read is the excitation
//! generator's sequence, checked in the board's own PWM timer counts.

use ridge_pump_firmware::excitation::Record;
use ridge_pump_firmware::lines::{ExciteLine, ValidateLine};
use ridge_pump_firmware::sfm3300::raw_to_counts;

/// A record as the firmware saw it: the duty (1/10 000) in effect at each read and the raw
/// word read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Samples {
    /// The excitation preset the duties follow (named on the `EXCITE` / `VALIDATE` line).
    pub record: Option<Record>,
    /// Duties, 1/10 000.
    pub u: Vec<u16>,
    /// SFM3300 raw words.
    pub raw: Vec<u16>,
    /// When each read happened, in the harness's time unit (0 for a host-made record).
    pub at: Vec<u64>,
    /// Operating point the firmware subtracts (`EXCITE … u0= y0=`): duty 1/10 000.
    pub u0: u16,
    /// Operating point flow, counts (`raw − 32768`).
    pub y0: i16,
    /// The operating point recomputed from the served frames as the firmware defines it:
    /// rounded mean (halves away from zero) of the 50 readings before the record.
    pub y0_frames: Option<i16>,
}

impl Samples {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// Whether empty.
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }
}

/// Rebuilds the record that the line `text` announces (`EXCITE <name> n=.. u0=.. y0=..` or
/// `VALIDATE <name> n=..`; its first byte left the UART at `line_at`) from `frames` (when each
/// frame was served, the raw word; in time order). `pwm_is(at, duty)`: whether the pump's PWM
/// in effect at `at` is what the board writes for `duty` (1/10 000), in its timer's counts.
/// The record starts within three frames of the line.
pub fn rebuild(
    text: &str,
    line_at: u64,
    frames: &[(u64, u16)],
    pwm_is: impl Fn(u64, u16) -> bool,
) -> Option<Samples> {
    // (preset name, samples, operating point: duty 1/10 000, flow counts; none on VALIDATE)
    let (name, n, u0, y0) = match ExciteLine::parse(text) {
        Ok(e) => (e.record, e.samples, e.u0, e.y0),
        Err(_) => {
            let v = ValidateLine::parse(text).ok()?;
            (v.record, v.samples, 0, 0)
        }
    };
    let record = name.parse::<Record>().ok()?;
    let gen: Vec<u16> = record.generator().take(n as usize).collect();
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
            let y0_frames = (k >= 50).then(|| {
                let sum: i32 = frames[k - 50..k]
                    .iter()
                    .map(|(_, raw)| i32::from(raw_to_counts(*raw)))
                    .sum();
                let half = if sum >= 0 { 25 } else { -25 };
                ((sum + half) / 50) as i16
            });
            let mut s = Samples {
                record: Some(record),
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
