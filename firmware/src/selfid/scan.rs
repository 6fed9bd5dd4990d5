//! The scan: the plant's lag from its start-up ([`Startup`]), and the duty ramps whose readings
//! give the static map from duty to flow ([`Scan`], `ridge_core::MapScan`).
//!
//! The lag `L` (ticks) is the flow's mean residence time after the start-up step of the first
//! settle phase, `N − Σy / y0` over its `N` readings (one running sum; a first-order lag `τ`
//! behind `d` ticks of dead time gives `d + τ`, the convex fan curve ~`d + 1.13 τ`), at least
//! the first tick the flow responds + 1. With a test lung the start-up overshoots (the empty
//! lung takes more than the settled flow) and the residence time comes out small or negative:
//! the first response bounds it then.
//!
//! Why a reading is credited to the duty `L` ticks before it, without undoing the lag's
//! derivative (`z = y + τ dy/dt`, `ridge_core::input_map`): the SFM3300's noise (3 % of the
//! reading) differenced and multiplied by `τ / Ts` (30 for the sluggish blower) leaves several
//! slm on a knot at high flows, while on a ramp a first-order lag *is* a delay of `τ`, and what
//! the delay gets wrong (an asymmetric lag, a lung) cancels to first order between the rising
//! and the falling side, whose mean each knot is. The turns of the scan (95 % and 15 %) lie
//! at or beyond the ends of the duty range the records and the breaths use.

use ridge_core::{InputMap, MapError, MapScan};

use super::config::Records;

/// A reading above this (counts, 0.5 slm) is the flow responding to the start-up step (the
/// SFM3300 reads its zero offset, ~0.1 slm, and its noise floor while the blower stands).
pub const RESPONSE_COUNTS: i16 = 60;

/// The lag measurement over a settle phase that started from rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Startup {
    /// Readings since the step.
    n: u16,
    /// Their sum, counts.
    sum: i32,
    /// Index of the first reading above [`RESPONSE_COUNTS`] (`u16::MAX` before it).
    first: u16,
}

impl Startup {
    pub(super) const fn new() -> Self {
        Startup {
            n: 0,
            sum: 0,
            first: u16::MAX,
        }
    }

    /// One reading (counts) taken after the step.
    pub(super) fn push(&mut self, counts: i16) {
        if self.first == u16::MAX && counts > RESPONSE_COUNTS {
            self.first = self.n;
        }
        self.n = self.n.saturating_add(1);
        self.sum = self.sum.saturating_add(i32::from(counts));
    }

    /// The lag, ticks, for the settled flow `y0` (counts): the mean residence time, at least
    /// the first response + 1 and 1, at most `max`; `None` when the flow never responded.
    pub(super) fn lag(&self, y0: i16, max: u8) -> Option<u8> {
        if self.first == u16::MAX || y0 <= RESPONSE_COUNTS {
            return None;
        }
        let y0 = i32::from(y0);
        // (N y0 − Σy) / y0: |N y0| ≤ 65 535 · 32 767 < 2³¹.
        let mrt = (i32::from(self.n) * y0 - self.sum) / y0;
        let floor = i32::from(self.first) + 1;
        // ≤ 255. Not `clamp`: its panic path for a bound pair out of order.
        Some(mrt.max(floor).min(i32::from(max)).max(1) as u8)
    }
}

/// The scan's duties and the map's accumulators.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Scan {
    /// Index of the next duty to apply (the interval that ended with the current reading is
    /// `next − 1`).
    pub(super) next: u16,
    /// The base duty, where the scan starts and ends.
    base: u16,
    /// Lag, ticks.
    pub(super) lag: u8,
    /// Every ramp duty has its reading: the map is due (`SelfIdentification::judge`).
    pub(super) complete: bool,
    /// Readings credited so far, and then the map.
    pub(super) map: Mapping,
}

/// The map while it is being measured, then the result (in the scan's place in the state
/// machine's phase storage: no box to put the accumulators in).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Mapping {
    /// Readings are being credited.
    Measuring(MapScan),
    /// The map.
    Done(InputMap),
}

impl Scan {
    pub(super) fn new(r: &Records, base: u16, lag: u8) -> Self {
        Scan {
            next: 0,
            base,
            lag,
            complete: false,
            map: Mapping::Measuring(MapScan::new(r.map_first, r.map_step)),
        }
    }

    /// Ticks of the three ramps.
    pub(super) fn ramp_ticks(&self, r: &Records) -> u16 {
        let (up, down, back) = legs(r, self.base);
        up.saturating_add(down).saturating_add(back)
    }

    /// Ticks in all: the ramps and the lead-in at the base duty.
    pub(super) fn len(&self, r: &Records) -> u16 {
        self.ramp_ticks(r)
            .saturating_add(u16::from(r.lead_in) * u16::from(self.lag))
    }

    /// The duty of tick `j` of the scan and whether it is rising; the base duty through the
    /// lead-in; `None` after it.
    pub(super) fn duty(&self, r: &Records, j: u16) -> Option<(u16, bool)> {
        let (up, down, back) = legs(r, self.base);
        let rate = r.scan_rate.max(1);
        let along = |k: u16| k.saturating_add(1).saturating_mul(rate);
        if j < up {
            return Some((self.base.saturating_add(along(j)).min(r.scan_high), true));
        }
        let j = j - up;
        if j < down {
            let top = r.scan_high.max(self.base);
            return Some((top.saturating_sub(along(j)).max(r.scan_low), false));
        }
        let j = j - down;
        if j < back {
            return Some((r.scan_low.saturating_add(along(j)).min(self.base), true));
        }
        (j - back < u16::from(r.lead_in) * u16::from(self.lag)).then_some((self.base, true))
    }

    /// Credits `reading` (counts; `None`: a sensor error, nothing credited), which ended the
    /// interval `next − 1`, to the ramp duty `lag` ticks before that interval. Returns `true`
    /// when that was the last ramp duty (the map is then due).
    pub(super) fn credit(&mut self, r: &Records, reading: Option<i16>) -> bool {
        let Some(ended) = self.next.checked_sub(1) else {
            return false;
        };
        let Some(at) = ended.checked_sub(u16::from(self.lag)) else {
            return false;
        };
        let ramps = self.ramp_ticks(r);
        if at >= ramps {
            return false;
        }
        let point = self.duty(r, at);
        let Mapping::Measuring(acc) = &mut self.map else {
            return false;
        };
        if let (Some(y), Some((u, rising))) = (reading, point) {
            acc.push(u, rising, y);
        }
        self.complete = at + 1 == ramps;
        self.complete
    }

    /// The map from the credited readings, once they are complete (see
    /// [`credit`](Self::credit)); `None` before, or when it was taken already.
    pub(super) fn finish(&mut self) -> Option<Result<InputMap, MapError>> {
        let Mapping::Measuring(acc) = &self.map else {
            return None;
        };
        if !self.complete {
            return None;
        }
        let result = acc.finish();
        if let Ok(map) = result {
            self.map = Mapping::Done(map);
        }
        Some(result)
    }

    /// The map, once [`finish`](Self::finish) made it.
    pub(super) fn map(&self) -> Option<InputMap> {
        match self.map {
            Mapping::Done(m) => Some(m),
            Mapping::Measuring(_) => None,
        }
    }
}

/// Ticks of the ramps from the base duty up to the top, down to the bottom, and back up to
/// the base duty.
fn legs(r: &Records, base: u16) -> (u16, u16, u16) {
    let rate = r.scan_rate.max(1);
    let ticks = |from: u16, to: u16| to.saturating_sub(from).div_ceil(rate);
    let top = r.scan_high.max(base);
    (
        ticks(base, top),
        ticks(r.scan_low, top),
        ticks(r.scan_low, base),
    )
}
