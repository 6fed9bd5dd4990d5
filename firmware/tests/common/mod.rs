//! A synthetic plant shared by the firmware's host tests (`mod common;` in each test file).
#![allow(dead_code)] // each test file uses its own part

use std::collections::VecDeque;

use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_OFFSET, FLOW_SCALE};

/// A linear first-order ARX plant with transport delay, in physical units:
/// `y_t = a y_{t-1} + b u_{t-d} + c + e_t` (slm, duty fraction), computed in SFM3300 counts
/// with the rounding to whole counts inside the recursion. `e_t` is a white equation error:
/// ±2 counts of uniform dither (a deterministic xorshift stream) plus the rounding, so the
/// plant *is* an ARX(1, 1, d) model and least squares is consistent. (Rounding only the
/// reading would be an output error, which ARX needs higher orders for; rounding without the
/// dither gets stuck in a dead band and makes a constant, not a white, error.)
#[derive(Clone, Debug)]
pub struct Plant {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: usize,
    y: f64,
    /// Inputs, newest last; `u_{t-d}` is `hist[len - 1 - d]`.
    hist: VecDeque<f64>,
    /// Overrides the reading (flat sensor, stalled pump...).
    pub stuck: Option<i16>,
    /// Dither state (xorshift64).
    rng: u64,
}

impl Plant {
    pub fn new(a: f64, b: f64, c: f64, d: usize) -> Self {
        Plant {
            a,
            b,
            c,
            d,
            y: 0.0,
            hist: VecDeque::from(vec![0.0; d + 1]),
            stuck: None,
            rng: 0x9E37_79B9_7F4A_7C15,
        }
    }

    /// The reference plant: τ ≈ 95 ms, gain 100 slm per unit duty, offset −10 slm, 3 samples
    /// of delay (20 slm at 30 % duty, 80 slm at 90 %).
    pub fn reference() -> Self {
        Plant::new(0.9, 10.0, -1.0, 3)
    }

    /// Applies `duty` (1/10 000) for one interval; returns the reading at its end (counts).
    pub fn step(&mut self, duty: u16) -> i16 {
        self.hist
            .push_back(f64::from(duty) / f64::from(DUTY_FULL_SCALE));
        self.hist.pop_front();
        let u = self.hist[self.hist.len() - 1 - self.d];
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        let dither = (self.rng >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0;
        let counts = ((self.a * self.y + self.b * u + self.c) * f64::from(FLOW_SCALE) + dither)
            .round()
            .clamp(-32768.0, 32767.0);
        self.y = counts / f64::from(FLOW_SCALE);
        match self.stuck {
            Some(c) => c,
            None => counts as i16,
        }
    }
}

/// The fake board's plant: the reading as the SFM3300's word (`counts + 32768`).
impl firmware_testkit::Plant for Plant {
    fn step_word(&mut self, duty: u16) -> u16 {
        (i32::from(self.step(duty)) + i32::from(FLOW_OFFSET)) as u16
    }
}
