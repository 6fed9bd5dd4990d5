//! The static input nonlinearity of a Hammerstein model: `v = g(u)`, piecewise linear, and its
//! estimation from a slow scan of the input range.
//!
//! A Hammerstein model is a static map followed by linear dynamics: `v_t = g(u_t)`, then the
//! ARX model of eq. (1) from `v` to `y`. For a blower the map is the steady flow at each duty
//! (fan law, dead zone, and with a lung the back pressure): it carries the nonlinearity, so that
//! one linear ARX model on `v` describes the plant over the whole flow range instead of around
//! one operating point. The structure search, the estimators and the controller design are the
//! linear ones, applied to `v` (docs/identification.md).
//!
//! [`InputMap`] keeps `g` as [`MAP_KNOTS`] values at equally spaced inputs
//! `u_k = first + k · step`, in the output's integer unit (the pump: SFM3300 counts), strictly
//! increasing so that it can be inverted ([`InputMap::inverse`]). Between knots it is linear,
//! beyond the ends it continues the end segments. Integer arithmetic only, no panics.
//!
//! [`MapScan`] estimates it from a record that moves the input through the range (the pump: a
//! ramp up and down). The plant's lag is undone before a reading is binned: for a first-order
//! lag with time constant `τ` behind a dead time of `d` samples, `z_t = y_t + (τ / T_s)(y_t −
//! y_{t−1})` is exactly `g(u_{t−d})`, whatever the input did before (no steady ramp, no settling
//! needed), so the caller pushes `z_t` with the input `d` samples back. Each knot averages the
//! values credited to it (the differences' noise telescopes: a bin's sum of `y_t − y_{t−1}` is
//! its last reading less its first), separately while the input rises and while it falls; the
//! knot is the mean of the two, which halves what an asymmetric lag (a blower coasting down
//! slower than it speeds up) leaves.

/// Knots of an [`InputMap`].
pub const MAP_KNOTS: usize = 16;

/// A strictly increasing piecewise-linear map `v = g(u)` (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputMap {
    /// Input of knot 0.
    first: u16,
    /// Input spacing of the knots (`> 0`).
    step: u16,
    /// `g(first + k · step)`, strictly increasing.
    knots: [i16; MAP_KNOTS],
}

/// Why a map cannot be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapError {
    /// `step` is 0, or the last knot's input exceeds `u16::MAX`.
    Grid,
    /// The values are not strictly increasing.
    NotIncreasing,
    /// The scan left no knot with readings on both sides of the range (fewer than 2 knots
    /// seen).
    Unscanned,
}

impl InputMap {
    /// A map through `knots` at inputs `first + k · step`; the values must be strictly
    /// increasing.
    pub const fn new(first: u16, step: u16, knots: [i16; MAP_KNOTS]) -> Result<Self, MapError> {
        let last = first as u32 + step as u32 * (MAP_KNOTS as u32 - 1);
        if step == 0 || last > u16::MAX as u32 {
            return Err(MapError::Grid);
        }
        let mut k = 1;
        while k < MAP_KNOTS {
            if knots[k] <= knots[k - 1] {
                return Err(MapError::NotIncreasing);
            }
            k += 1;
        }
        Ok(InputMap { first, step, knots })
    }

    /// Input of knot 0.
    pub const fn first(&self) -> u16 {
        self.first
    }

    /// Input spacing of the knots.
    pub const fn step(&self) -> u16 {
        self.step
    }

    /// The knot values.
    pub const fn knots(&self) -> &[i16; MAP_KNOTS] {
        &self.knots
    }

    /// Segment of `u` (0..MAP_KNOTS − 1, the end segments extended) and its offset from the
    /// segment's first knot, in input units (negative before knot 0).
    fn segment(&self, u: u16) -> (usize, i32) {
        let rel = i32::from(u) - i32::from(self.first);
        let step = i32::from(self.step);
        let k = if rel <= 0 {
            0
        } else {
            ((rel / step) as usize).min(MAP_KNOTS - 2)
        };
        (k, rel - k as i32 * step)
    }

    /// `g(u)` rounded down, saturated to the `i16` range.
    pub fn at(&self, u: u16) -> i16 {
        let (k, off) = self.segment(u);
        let (a, b) = (self.value(k), self.value(k + 1));
        let v =
            i32::from(a) + ((i32::from(b) - i32::from(a)) * off).div_euclid(i32::from(self.step));
        v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
    }

    fn value(&self, k: usize) -> i16 {
        self.knots.get(k).copied().unwrap_or(0)
    }

    /// The input `u` with `g(u) = v` (rounded down), saturated to `0..=u16::MAX`.
    pub fn inverse(&self, v: i16) -> u16 {
        // The segment whose values bracket v (the end segments extended).
        let mut k = 0;
        while k + 2 < MAP_KNOTS && v >= self.value(k + 1) {
            k += 1;
        }
        let (a, b) = (i32::from(self.value(k)), i32::from(self.value(k + 1)));
        let u0 = i32::from(self.first) + k as i32 * i32::from(self.step);
        let u = u0 + ((i32::from(v) - a) * i32::from(self.step)).div_euclid(b - a);
        u.clamp(0, i32::from(u16::MAX)) as u16
    }
}

/// An [`InputMap`] prepared for a control loop ([`InputMap::table`]): the segment found by
/// comparisons and one fixed-point slope per segment each way, so that [`at`](Self::at) and
/// [`inverse`](Self::inverse) cost a multiplication and a shift instead of a division (on the
/// ATmega2560 a 32-bit division is ~600 cycles of a 25 600-cycle control tick).
///
/// Results are those of the exact map rounded down, or one unit below them (the slopes are
/// rounded down to 1/65 536); before the first knot, where the extended segment is walked
/// backwards, one unit above is possible too. Within one unit of [`InputMap::at`] and
/// [`InputMap::inverse`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MapTable {
    first: u16,
    step: u16,
    knots: [i16; MAP_KNOTS],
    /// Per segment `k`: `(g_{k+1} − g_k) · 2¹⁶ / step`, rounded down, saturated.
    forward: [u32; MAP_KNOTS - 1],
    /// Per segment `k`: `step · 2¹⁶ / (g_{k+1} − g_k)`, rounded down.
    inverse: [u32; MAP_KNOTS - 1],
}

impl InputMap {
    /// The map prepared for repeated evaluation (see [`MapTable`]).
    pub fn table(&self) -> MapTable {
        let mut forward = [0u32; MAP_KNOTS - 1];
        let mut inverse = [0u32; MAP_KNOTS - 1];
        let step = u64::from(self.step.max(1));
        for k in 0..MAP_KNOTS - 1 {
            // Strictly increasing (`InputMap::new`): 1 ≤ dv ≤ 65 535.
            let dv = (i32::from(self.value(k + 1)) - i32::from(self.value(k))).max(1) as u64;
            let f = (dv << 16) / step;
            forward[k] = u32::try_from(f).unwrap_or(u32::MAX);
            // step · 2¹⁶ / dv ≤ 65 535 · 65 536 < 2³².
            inverse[k] = u32::try_from((step << 16) / dv).unwrap_or(u32::MAX);
        }
        MapTable {
            first: self.first,
            step: self.step,
            knots: self.knots,
            forward,
            inverse,
        }
    }
}

/// `base + off · slope / 2¹⁶` rounded down (for `off < 0` the product is rounded up before it
/// is taken away), saturated to `base ± 65 535`.
fn along(base: i32, off: i32, slope: u32) -> i32 {
    let product = off.unsigned_abs().saturating_mul(slope);
    if off < 0 {
        // ≤ 65 536 after the shift.
        base - (product.saturating_add(0xFFFF) >> 16) as i32
    } else {
        base + (product >> 16) as i32
    }
}

impl MapTable {
    /// The map it was made from.
    pub fn map(&self) -> InputMap {
        InputMap {
            first: self.first,
            step: self.step,
            knots: self.knots,
        }
    }

    /// `g(u)` (the end segments extended), saturated to the `i16` range: the exact value
    /// rounded down, or one below (before the first knot: or one above).
    pub fn at(&self, u: u16) -> i16 {
        // The last knot at or below u (0 below the first), at most the last segment's start.
        let mut k = 0;
        let mut start = self.first;
        while k + 2 < MAP_KNOTS {
            let next = start.saturating_add(self.step);
            if u < next {
                break;
            }
            start = next;
            k += 1;
        }
        let v0 = i32::from(self.knots.get(k).copied().unwrap_or(0));
        let slope = self.forward.get(k).copied().unwrap_or(0);
        let v = along(v0, i32::from(u) - i32::from(start), slope);
        v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
    }

    /// The input `u` with `g(u) = v` (the end segments extended), saturated to
    /// `0..=u16::MAX`: the exact value rounded down, or one below (below the first knot's
    /// value: or one above).
    pub fn inverse(&self, v: i16) -> u16 {
        let mut k = 0;
        while k + 2 < MAP_KNOTS && v >= self.knots.get(k + 1).copied().unwrap_or(i16::MAX) {
            k += 1;
        }
        let v0 = self.knots.get(k).copied().unwrap_or(0);
        let slope = self.inverse.get(k).copied().unwrap_or(0);
        let start = i32::from(self.first) + k as i32 * i32::from(self.step);
        let u = along(start, i32::from(v) - i32::from(v0), slope);
        u.clamp(0, i32::from(u16::MAX)) as u16
    }
}

/// The accumulators of a scan (see the [module docs](self)): per knot, the sum and count of
/// the readings credited to it on the up ramp and on the down ramp.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MapScan {
    first: u16,
    step: u16,
    /// Per side (rising, falling) and knot: sum of the values credited.
    sum: [[i32; MAP_KNOTS]; 2],
    /// The inputs' offsets from the knot, summed (a bin at the end of the scan is one-sided).
    off: [[i32; MAP_KNOTS]; 2],
    n: [[u16; MAP_KNOTS]; 2],
}

impl MapScan {
    /// Empty accumulators for the knot grid `first + k · step`.
    pub const fn new(first: u16, step: u16) -> Self {
        MapScan {
            first,
            step,
            sum: [[0; MAP_KNOTS]; 2],
            off: [[0; MAP_KNOTS]; 2],
            n: [[0; MAP_KNOTS]; 2],
        }
    }

    /// Credits reading `y` to the input `u_lagged` applied `lag` samples before it, on the up
    /// ramp (`rising`) or the down ramp. Inputs farther than half a step from every knot are
    /// ignored.
    pub fn push(&mut self, u_lagged: u16, rising: bool, y: i16) {
        if self.step == 0 {
            return;
        }
        let rel = i32::from(u_lagged) - i32::from(self.first) + i32::from(self.step / 2);
        if rel < 0 {
            return;
        }
        let k = (rel / i32::from(self.step)) as usize;
        let off = rel - k as i32 * i32::from(self.step) - i32::from(self.step / 2);
        let side = usize::from(!rising);
        if let (Some(s), Some(o), Some(n)) = (
            self.sum.get_mut(side).and_then(|r| r.get_mut(k)),
            self.off.get_mut(side).and_then(|r| r.get_mut(k)),
            self.n.get_mut(side).and_then(|r| r.get_mut(k)),
        ) {
            *s = s.saturating_add(i32::from(y));
            *o = o.saturating_add(off);
            *n = n.saturating_add(1);
        }
    }

    /// The map: each knot the mean of its up and down means (one side's where the other has
    /// none), each mean moved from its inputs' mean to the knot along the map's local slope (the
    /// bins at the ends of a scan hold inputs on one side of their knot only); knots the scan
    /// did not reach extrapolated from the nearest two it did; then made strictly increasing
    /// (each knot at least one unit above the one before: a dead zone becomes a shallow slope
    /// that still inverts).
    pub fn finish(&self) -> Result<InputMap, MapError> {
        // Per knot: value at the inputs' mean, and that mean's offset from the knot.
        let mut at = [(0i32, 0i32); MAP_KNOTS];
        let mut seen = [false; MAP_KNOTS];
        for k in 0..MAP_KNOTS {
            let mean = |v: i32, n: i32| {
                let half = if v >= 0 { n / 2 } else { -(n / 2) };
                (v + half) / n
            };
            let side = |s: usize| {
                let n = i32::from(self.n[s][k]);
                (n > 0).then(|| (mean(self.sum[s][k], n), mean(self.off[s][k], n)))
            };
            let v = match (side(0), side(1)) {
                (Some(a), Some(b)) => Some(((a.0 + b.0) / 2, (a.1 + b.1) / 2)),
                (Some(a), None) | (None, Some(a)) => Some(a),
                (None, None) => None,
            };
            if let Some(v) = v {
                at[k] = v;
                seen[k] = true;
            }
        }
        // The local slope from the neighbours seen, per input unit ×1/step: move each mean to
        // its knot.
        let mut knots = [0i16; MAP_KNOTS];
        for k in 0..MAP_KNOTS {
            if !seen[k] {
                continue;
            }
            let before = (0..k).rev().find(|&j| seen[j]);
            let after = (k + 1..MAP_KNOTS).find(|&j| seen[j]);
            let slope = match (before, after) {
                (Some(b), Some(a)) => Some((at[a].0 - at[b].0, (a - b) as i32)),
                (Some(b), None) => Some((at[k].0 - at[b].0, (k - b) as i32)),
                (None, Some(a)) => Some((at[a].0 - at[k].0, (a - k) as i32)),
                (None, None) => None,
            };
            let shift = match slope {
                Some((dv, dk)) => -(dv * at[k].1) / (dk * i32::from(self.step)),
                None => 0,
            };
            knots[k] = (at[k].0 + shift).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        }
        let lo = seen.iter().position(|&s| s);
        let hi = seen.iter().rposition(|&s| s);
        let (Some(lo), Some(hi)) = (lo, hi) else {
            return Err(MapError::Unscanned);
        };
        if hi <= lo {
            return Err(MapError::Unscanned);
        }
        // Gaps inside the scanned range: linear between the neighbours seen.
        let mut prev = lo;
        for k in lo + 1..=hi {
            if seen[k] {
                for j in prev + 1..k {
                    let (a, b) = (i32::from(knots[prev]), i32::from(knots[k]));
                    knots[j] = (a + (b - a) * (j - prev) as i32 / (k - prev) as i32) as i16;
                }
                prev = k;
            }
        }
        // Beyond the scanned range: the end segments continued.
        let next_lo = (lo + 1..=hi).find(|&k| seen[k]).unwrap_or(hi);
        let prev_hi = (lo..hi).rev().find(|&k| seen[k]).unwrap_or(lo);
        for k in 0..lo {
            let slope = (i32::from(knots[next_lo]) - i32::from(knots[lo])) / (next_lo - lo) as i32;
            knots[k] = (i32::from(knots[lo]) - slope * (lo - k) as i32)
                .clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        }
        for k in hi + 1..MAP_KNOTS {
            let slope = (i32::from(knots[hi]) - i32::from(knots[prev_hi])) / (hi - prev_hi) as i32;
            knots[k] = (i32::from(knots[hi]) + slope * (k - hi) as i32)
                .clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        }
        for k in 1..MAP_KNOTS {
            if knots[k] <= knots[k - 1] {
                knots[k] = knots[k - 1].saturating_add(1);
            }
        }
        InputMap::new(self.first, self.step, knots)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blower-like static map: 0 below 12 %, then 150 slm · s^1.3 with s the speed fraction,
    /// in SFM3300 counts (120 per slm).
    fn truth(u: f64) -> f64 {
        let s = ((u / 10_000.0 - 0.12) / 0.88).max(0.0);
        120.0 * 150.0 * libm::pow(s, 1.3)
    }

    #[test]
    fn evaluates_and_inverts_between_and_beyond_the_knots() {
        let mut knots = [0i16; MAP_KNOTS];
        for (k, v) in knots.iter_mut().enumerate() {
            *v = (100 + 37 * k * k) as i16;
        }
        let m = InputMap::new(1_500, 500, knots).unwrap();
        // At the knots, halfway between (linear), and extended beyond both ends.
        assert_eq!(m.at(1_500), 100);
        assert_eq!(m.at(2_000), 137);
        assert_eq!(m.at(2_250), (137 + 248) / 2);
        assert_eq!(m.at(1_000), 100 - 37);
        assert_eq!(m.at(1_250), 100 - 19); // -18.5 rounded down
        let last = 1_500 + 15 * 500;
        let slope = knots[15] - knots[14];
        assert_eq!(m.at(last + 500), knots[15] + slope);
        // The inverse undoes the map to within one input step of the map's resolution.
        for u in (0..12_000u16).step_by(7) {
            let v = m.at(u);
            let back = m.inverse(v);
            assert!(
                m.at(back) <= v && m.at(back.saturating_add(1)) >= v,
                "{u} {v} {back}"
            );
        }
        assert_eq!(InputMap::new(0, 0, knots), Err(MapError::Grid));
        assert_eq!(InputMap::new(60_000, 500, knots), Err(MapError::Grid));
        knots[5] = knots[4];
        assert_eq!(
            InputMap::new(1_500, 500, knots),
            Err(MapError::NotIncreasing)
        );
    }

    /// A scan of a first-order plant (`tau`, `delay` samples of dead time) behind the map
    /// `truth`, settled at 20 %: up to 85 % at `rate` units per sample, `dwell` samples there,
    /// down to 20 % and `dwell` samples there. With `undo_lag` each reading is pushed as
    /// `z = y + τ dy/dt` with the input `delay` samples back (as the pump's scan does);
    /// without, as read, with the input of the same sample.
    fn scan(tau: f64, delay: usize, rate: u16, dwell: usize, undo_lag: bool) -> InputMap {
        let a = libm::exp(-0.01 / tau);
        let mut duties = [0u16; 2_000];
        let mut starts = [0usize; 4];
        let mut n = 0;
        let mut u = 2_000u16;
        while u < 8_500 {
            duties[n] = u;
            n += 1;
            u += rate;
        }
        starts[1] = n;
        for _ in 0..dwell {
            duties[n] = 8_500;
            n += 1;
        }
        starts[2] = n;
        u = 8_500;
        while u > 2_000 {
            duties[n] = u;
            n += 1;
            u -= rate;
        }
        starts[3] = n;
        for _ in 0..dwell {
            duties[n] = 2_000;
            n += 1;
        }
        let mut y = truth(2_000.0);
        let mut scan = MapScan::new(1_500, 500);
        let k = if undo_lag { tau / 0.01 } else { 0.0 };
        for t in 0..n {
            let drive = duties[t.saturating_sub(delay)];
            let prev = y;
            y = a * y + (1.0 - a) * truth(f64::from(drive));
            // The lag undone: z = y + τ dy/dt is the map at the input `delay` samples back.
            let z = y + k * (y - prev);
            let back = if undo_lag { delay } else { 0 };
            if let Some(s) = t.checked_sub(back) {
                let seg = starts.iter().rposition(|&b| s >= b).unwrap_or(0);
                scan.push(duties[s], seg < 2, z as i16);
            }
        }
        scan.finish().unwrap()
    }

    #[test]
    fn a_scan_recovers_the_static_map_of_a_lagging_plant() {
        // τ = 0.3 s, 5 samples of dead time, 2 s ramps over 65 % with no dwell at the turns:
        // the reading trails the input by 10 % of the range. With the lag undone the map is
        // within 0.5 slm of the true one from 20 % to 85 % (measured 0.38); read as is, off by
        // more than 10 (measured 22.6, at the steep top of the fan curve).
        let worst = |m: &InputMap| {
            (2..=14)
                .map(|k| {
                    let u = 1_500 + 500 * k as u16;
                    libm::fabs(f64::from(m.at(u)) - truth(f64::from(u))) / 120.0
                })
                .fold(0.0, f64::max)
        };
        let compensated = scan(0.3, 5, 33, 0, true);
        assert!(worst(&compensated) < 0.5, "{}", worst(&compensated));
        let naive = scan(0.3, 5, 33, 0, false);
        assert!(worst(&naive) > 10.0, "{}", worst(&naive));
        // Knots outside the scan (15 %, 90 %) come from the end segments, and the map inverts.
        let m = compensated;
        assert!(m.at(1_500) < m.at(2_000) && m.at(9_000) > m.at(8_500));
        for k in 1..MAP_KNOTS {
            assert!(m.knots()[k] > m.knots()[k - 1]);
        }
    }

    /// The exact map of `m` at `u` in rationals (f64), the end segments extended.
    fn exact_at(m: &InputMap, u: f64) -> f64 {
        let k = ((u - f64::from(m.first())) / f64::from(m.step())).floor();
        let k = k.clamp(0.0, (MAP_KNOTS - 2) as f64) as usize;
        let u0 = f64::from(m.first()) + k as f64 * f64::from(m.step());
        let (a, b) = (f64::from(m.knots()[k]), f64::from(m.knots()[k + 1]));
        a + (b - a) * (u - u0) / f64::from(m.step())
    }

    /// The exact inverse of `m` at `v`, the end segments extended.
    fn exact_inverse(m: &InputMap, v: f64) -> f64 {
        let mut k = 0;
        while k + 2 < MAP_KNOTS && v >= f64::from(m.knots()[k + 1]) {
            k += 1;
        }
        let u0 = f64::from(m.first()) + k as f64 * f64::from(m.step());
        let (a, b) = (f64::from(m.knots()[k]), f64::from(m.knots()[k + 1]));
        u0 + (v - a) * f64::from(m.step()) / (b - a)
    }

    #[test]
    fn the_table_evaluates_and_inverts_without_division_within_one_unit() {
        // A blower map (flat dead zone, steep top), a map with one-count segments and one
        // with huge ones: everywhere, inside and beyond the knots, the table is the exact
        // value rounded down or one below it.
        let mut blower = [0i16; MAP_KNOTS];
        for (k, v) in blower.iter_mut().enumerate() {
            *v = truth(1_500.0 + 533.0 * k as f64).round() as i16 + k as i16;
        }
        let mut flat = [0i16; MAP_KNOTS];
        for (k, v) in flat.iter_mut().enumerate() {
            *v = -7 + k as i16;
        }
        let mut steep = [0i16; MAP_KNOTS];
        for (k, v) in steep.iter_mut().enumerate() {
            *v = (-30_000 + 3_900 * k as i32) as i16;
        }
        for (first, step, knots) in [(1_500, 533, blower), (2_000, 500, flat), (100, 7, steep)] {
            let m = InputMap::new(first, step, knots).unwrap();
            let t = m.table();
            assert_eq!(t.map(), m);
            for u in (0..=u16::MAX).step_by(3) {
                let exact = exact_at(&m, f64::from(u))
                    .floor()
                    .clamp(-32_768.0, 32_767.0);
                let got = f64::from(t.at(u));
                let above = u < first && got == exact + 1.0;
                assert!(
                    got == exact || got == exact - 1.0 || above,
                    "at({u}) = {got}, exact {exact}"
                );
                assert!((i32::from(t.at(u)) - i32::from(m.at(u))).abs() <= 1);
            }
            for v in (i16::MIN..=i16::MAX).step_by(3) {
                let exact = exact_inverse(&m, f64::from(v)).floor().clamp(0.0, 65_535.0);
                let got = f64::from(t.inverse(v));
                let above = v < knots[0] && got == exact + 1.0;
                assert!(
                    got == exact || got == exact - 1.0 || above,
                    "inverse({v}) = {got}, exact {exact}"
                );
                assert!((i32::from(t.inverse(v)) - i32::from(m.inverse(v))).abs() <= 1);
            }
        }
    }

    #[test]
    fn an_empty_or_one_knot_scan_is_refused() {
        let mut s = MapScan::new(1_500, 500);
        assert_eq!(s.finish(), Err(MapError::Unscanned));
        s.push(3_000, true, 500);
        s.push(3_010, false, 520);
        assert_eq!(s.finish(), Err(MapError::Unscanned));
        s.push(3_500, true, 900);
        assert!(s.finish().is_ok());
    }
}
