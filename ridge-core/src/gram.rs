//! Exact streaming statistics of an input/output record.
//!
//! A [`Gram`] takes one `(u_t, y_t)` sample at a time and keeps everything needed to
//! form `XᵀX`, `Xᵀy` and `yᵀy` of the zero-padded regression matrix of eq. (6) for
//! every structure `p ≤ P_MAX`, `q + d ≤ Q_MAX + D_MAX`, with or without an intercept.
//! Memory is independent of the record length: 39 running correlations, two sums,
//! the sample count and the last 12 inputs and 7 outputs.
//!
//! Lagged products are Toeplitz up to edge terms: with zero history before the record,
//! `Σ_{t=1..N} a_{t-i} b_{t-j} = Σ_{s=1..N} a_s b_{s-(j-i)} − Σ_{s=N-i+1..N} a_s b_{s-(j-i)}`
//! for `i ≤ j`, so one running correlation per lag difference plus a correction from
//! the last few samples reproduces every entry of the 20 × 20 lag Gram exactly.
//!
//! Two accumulators:
//! - [`IntGram`] (`Gram<i64>`) takes raw integer counts (`i32`: SFM3300 words minus
//!   32768, PWM compare values, …). Sums are exact whatever `N`; overflow is detected
//!   before it can happen and reported as [`Error::Overflow`].
//! - [`FloatGram`] (`Gram<f64>`) takes physical values (`f64` or `f32` widened).
//!   NaN and ±∞ are rejected with [`Error::NonFinite`].
//!
//! [`MeasuredGram`] gives the statistics from measured initial conditions (the first `m`
//! samples fill the lag history and contribute no row) from two such accumulators.
//!
//! Scale factors ([`Scale`]) turn counts into physical units once, at solve time
//! ([`Gram::normal`]), so coefficients come out in physical units whichever path
//! fed the statistics.

use crate::error::{Error, Result};
use crate::normal::{other, Col, Normal, N_OTHER};
use crate::real::Real;
use crate::structure::Grid;
use crate::wide::Wide;
use crate::{L_MAX, P_MAX};

/// Physical units per raw count for the input and the output.
///
/// Example: SFM3300 flow in slm from `raw − 32768` counts is `1/120` slm per count;
/// a duty given in 1/10 000 of full scale is `1e-4` per count (the pump's scale is
/// `ridge_pump_firmware::units::SCALE`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scale {
    /// Input units per count (e.g. duty fraction per PWM count).
    pub u: f64,
    /// Output units per count (e.g. slm per SFM3300 count).
    pub y: f64,
}

impl Scale {
    /// No conversion: the samples already are physical values.
    pub const UNIT: Scale = Scale { u: 1.0, y: 1.0 };
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for i64 {}
    impl Sealed for f64 {}
}

/// An accumulator type of a [`Gram`]: `i64` (exact, integer samples) or `f64`.
pub trait Accumulator: Copy + Default + core::fmt::Debug + PartialEq + sealed::Sealed {
    /// One sample as pushed: `i32` counts for `i64`, `f64` values for `f64`.
    type Sample: Copy + Default + core::fmt::Debug + PartialEq;
    /// Rejects samples the accumulator cannot take (NaN, ±∞).
    fn check_sample(s: Self::Sample) -> Result<()>;
    /// `|s|` as an accumulator value.
    fn magnitude(s: Self::Sample) -> Self;
    /// A sample count up to which the sums cannot overflow when every sample is bounded by
    /// `max_abs` (each sum is at most `n · max_abs²`); may be below the largest such count
    /// (the integer path rounds it down to a power of two, at most a factor 8).
    fn capacity(max_abs: Self) -> u32;
    /// `a · b` as an accumulator value.
    fn product(a: Self::Sample, b: Self::Sample) -> Self;
    /// `s` as an accumulator value.
    fn widen(s: Self::Sample) -> Self;
    /// `self + other` (cannot overflow within [`Accumulator::capacity`]).
    fn plus(self, other: Self) -> Self;
    /// `self − other` (cannot overflow within [`Accumulator::capacity`]).
    fn minus(self, other: Self) -> Self;
    /// `true` for zero.
    fn is_zero(self) -> bool;
    /// `(s11 · sab − sa1 · sb1) / s11` in `T`: the Schur complement of one entry with
    /// respect to the first pivot, its numerator computed exactly (128-bit) for integer
    /// statistics.
    ///
    /// By reference: four 64-bit values by value would spill to the stack on AVR.
    fn schur<T: Real>(s11: &Self, sab: &Self, sa1: &Self, sb1: &Self) -> Result<T>;
    /// `n · Σs² − (Σs)²` is zero or numerically zero: the signal is constant.
    fn is_constant(n: u32, sum: Self, sum_sq: Self) -> bool;
    /// Rounding level of the statistics of a signal with `Σs² = sum_sq` over `n`
    /// samples, in raw units squared: zero for exact integer sums, about
    /// `8 (√n + 2) ε₆₄ Σs²` for `f64` sums (accumulation plus the pivot elimination).
    fn rounding(n: u32, sum_sq: Self) -> f64;
    /// Converts to `T`.
    fn to_real<T: Real>(self) -> T;
    /// A sample count as an accumulator value.
    fn widen_count(n: u32) -> Self;
    /// `true` for values above zero.
    fn is_positive(self) -> bool;
}

impl Accumulator for i64 {
    type Sample = i32;
    #[inline]
    fn check_sample(_: i32) -> Result<()> {
        Ok(())
    }
    #[inline]
    fn magnitude(s: i32) -> i64 {
        i64::from(s).abs()
    }
    #[inline]
    fn capacity(max_abs: i64) -> u32 {
        // Every accumulator is bounded by n · max², every sum by n · max ≤ n · max². With
        // `max ≤ 2^b`, `n ≤ 2^(62 − 2b)` keeps `n · max² ≤ 2^62 < 2^63`: at most a factor 8
        // below the exact bound (16-bit counts get the whole u32 range). Found by shifting,
        // not by `i64::MAX / max²` (a 64-bit division costs ~4000 cycles on an 8-bit MCU, in
        // the tick where a new extreme arrives) nor `leading_zeros`/`saturating_mul` on `u64`
        // (1.2 KB of inline AVR code).
        let mut m = max_abs.unsigned_abs().saturating_sub(1); // < 2^b ⇔ max ≤ 2^b
        let mut b = 0u32;
        while m != 0 {
            m >>= 1;
            b += 1;
        }
        match 62u32.checked_sub(2 * b) {
            Some(shift) if shift < 32 => 1u32 << shift,
            Some(_) => u32::MAX,
            None => 0,
        }
    }
    #[inline]
    fn product(a: i32, b: i32) -> i64 {
        // Sensor and PWM counts fit in 16 bits: on an 8-bit MCU a 16 × 16 → 32-bit
        // multiply is far cheaper than a 64-bit one. 32-bit cores have a widening
        // multiply instruction and take the plain path.
        #[cfg(target_arch = "avr")]
        if let (Ok(a), Ok(b)) = (i16::try_from(a), i16::try_from(b)) {
            return i64::from(i32::from(a) * i32::from(b));
        }
        i64::from(a) * i64::from(b)
    }
    #[inline]
    fn widen(s: i32) -> i64 {
        i64::from(s)
    }
    #[inline]
    fn plus(self, other: i64) -> i64 {
        self.wrapping_add(other)
    }
    #[inline]
    fn minus(self, other: i64) -> i64 {
        self.wrapping_sub(other)
    }
    #[inline]
    fn is_zero(self) -> bool {
        self == 0
    }
    fn schur<T: Real>(s11: &i64, sab: &i64, sa1: &i64, sb1: &i64) -> Result<T> {
        // Exact: |S| < 2^63 (capacity), so both products are below 2^126 and their
        // difference fits in 128 bits.
        let mut num = Wide::product(s11, sab);
        num.sub_product(sa1, sb1);
        Ok(num.to_real::<T>() / T::from_i64(*s11))
    }
    fn rounding(_: u32, _: i64) -> f64 {
        0.0
    }
    // Inlined: out of line its 20 bytes of arguments are more than the AVR argument
    // registers hold, and the ATmega2560 build reads arguments passed on the stack one byte
    // off (see `wide.rs`; `avr-stack` checks the images).
    #[inline(always)]
    fn is_constant(n: u32, sum: i64, sum_sq: i64) -> bool {
        let mut var = Wide::product(&i64::from(n), &sum_sq);
        var.sub_product(&sum, &sum);
        var.is_negative() || var.is_zero()
    }
    #[inline]
    fn to_real<T: Real>(self) -> T {
        T::from_i64(self)
    }
    fn widen_count(n: u32) -> Self {
        i64::from(n)
    }
    fn is_positive(self) -> bool {
        self > 0
    }
}

impl Accumulator for f64 {
    type Sample = f64;
    #[inline]
    fn check_sample(s: f64) -> Result<()> {
        if s.is_finite() {
            Ok(())
        } else {
            Err(Error::NonFinite)
        }
    }
    #[inline]
    fn magnitude(s: f64) -> f64 {
        libm::fabs(s)
    }
    #[inline]
    fn capacity(max_abs: f64) -> u32 {
        let sq = max_abs * max_abs;
        if sq <= 1e300 / f64::from(u32::MAX) {
            u32::MAX
        } else {
            // Truncation towards zero is the safe side; ∞ or NaN give 0.
            let c = 1e300 / sq;
            if c >= 1.0 {
                c as u32
            } else {
                0
            }
        }
    }
    #[inline]
    fn product(a: f64, b: f64) -> f64 {
        a * b
    }
    #[inline]
    fn widen(s: f64) -> f64 {
        s
    }
    #[inline]
    fn plus(self, other: f64) -> f64 {
        self + other
    }
    #[inline]
    fn minus(self, other: f64) -> f64 {
        self - other
    }
    #[inline]
    fn is_zero(self) -> bool {
        self == 0.0
    }
    fn schur<T: Real>(s11: &f64, sab: &f64, sa1: &f64, sb1: &f64) -> Result<T> {
        let v = sab - sa1 * (sb1 / s11);
        if v.is_finite() {
            Ok(T::from_f64(v))
        } else {
            Err(Error::Overflow)
        }
    }
    fn rounding(n: u32, sum_sq: f64) -> f64 {
        8.0 * (libm::sqrt(f64::from(n)) + 2.0) * f64::EPSILON * sum_sq
    }
    fn is_constant(n: u32, sum: f64, sum_sq: f64) -> bool {
        let n = f64::from(n);
        let var = n * sum_sq - sum * sum;
        var <= 1e-12 * n * sum_sq
    }
    #[inline]
    fn to_real<T: Real>(self) -> T {
        T::from_f64(self)
    }
    fn widen_count(n: u32) -> Self {
        f64::from(n)
    }
    fn is_positive(self) -> bool {
        self > 0.0
    }
}

/// Exact streaming statistics of one record; see the [module docs](self).
///
/// # Example
/// ```
/// use ridge_core::{IntGram, Scale, Structure, Offset};
/// let mut gram = IntGram::new();
/// for t in 0..400i32 {
///     let u = if (t / 20) % 2 == 0 { 3000 } else { 6000 }; // duty, 1/10 000
///     let y = 0; // SFM3300 counts, raw − 32768 (a real sensor goes here)
///     gram.push(u, y + (t % 7) * 40)?;
/// }
/// // Duty fraction per count, slm per count.
/// let normal = gram.normal::<f32>(Scale { u: 1e-4, y: 1.0 / 120.0 })?;
/// let system = normal.system(Structure::new(2, 2, 1)?, Offset::None)?;
/// assert_eq!(system.samples(), 400);
/// # Ok::<(), ridge_core::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Gram<A: Accumulator> {
    n: u32,
    /// `Σ y_s y_{s-k}`, `k = 0..=P_MAX`.
    yy: [A; P_MAX + 1],
    /// `Σ u_s u_{s-k}`, `k = 0..L_MAX`.
    uu: [A; L_MAX],
    /// `Σ y_s u_{s-k}`, `k = 0..L_MAX`.
    yu: [A; L_MAX],
    /// `Σ u_s y_{s-k}`, `k = 1..=P_MAX` (index `k − 1`).
    uy: [A; P_MAX],
    sum_y: A,
    sum_u: A,
    /// Largest `|sample|` seen, for the overflow check.
    max_abs: A,
    /// Sample count up to which the sums cannot overflow at `max_abs`.
    capacity: u32,
    /// `y_hist[k] = y_{N-k}` (zero before the record).
    y_hist: [A::Sample; P_MAX + 1],
    /// `u_hist[k] = u_{N-k}` (zero before the record).
    u_hist: [A::Sample; L_MAX],
}

/// Exact integer statistics: samples are `i32` counts, sums `i64`.
pub type IntGram = Gram<i64>;
/// Floating-point statistics: samples are `f64` physical values, sums `f64`.
pub type FloatGram = Gram<f64>;

impl<A: Accumulator> Default for Gram<A> {
    fn default() -> Self {
        Self::new()
    }
}

impl<A: Accumulator> Gram<A> {
    /// Empty statistics (zero history).
    pub fn new() -> Self {
        Gram {
            n: 0,
            yy: [A::default(); P_MAX + 1],
            uu: [A::default(); L_MAX],
            yu: [A::default(); L_MAX],
            uy: [A::default(); P_MAX],
            sum_y: A::default(),
            sum_u: A::default(),
            max_abs: A::default(),
            capacity: u32::MAX,
            y_hist: [A::Sample::default(); P_MAX + 1],
            u_hist: [A::Sample::default(); L_MAX],
        }
    }

    /// Number of samples pushed.
    pub fn len(&self) -> u32 {
        self.n
    }

    /// `true` before the first sample.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Adds the sample `(u_t, y_t)`: `u_t` is the input applied during the interval
    /// that ends with the measurement `y_t` (so `d = 0` is a causal model).
    ///
    /// Errors: [`Error::NonFinite`] for NaN/±∞ (float path), [`Error::Overflow`] when
    /// the sums could overflow. On error the statistics are unchanged.
    pub fn push(&mut self, u: A::Sample, y: A::Sample) -> Result<()> {
        self.push_lags(u, y, P_MAX + 1, L_MAX)
    }

    /// [`Gram::push`] updating only the statistics of output lags `0..outputs` and input lags
    /// `0..inputs` (`outputs ≤ P_MAX + 1`, `inputs ≤ L_MAX`): entries of other lags are left
    /// out of date ([`MeasuredGram::for_grid`]).
    #[inline(always)]
    fn push_lags(
        &mut self,
        u: A::Sample,
        y: A::Sample,
        outputs: usize,
        inputs: usize,
    ) -> Result<()> {
        A::check_sample(u)?;
        A::check_sample(y)?;
        let mu = A::magnitude(u);
        let my = A::magnitude(y);
        let mut max_abs = self.max_abs;
        let mut capacity = self.capacity;
        for m in [mu, my] {
            if m.minus(max_abs).is_positive() {
                max_abs = m;
                // Rare (only when a new extreme arrives): the division stays off the
                // per-sample path, which matters on an 8-bit MCU.
                capacity = A::capacity(max_abs);
            }
        }
        let n = self.n.checked_add(1).ok_or(Error::Overflow)?;
        if n > capacity {
            return Err(Error::Overflow);
        }
        self.max_abs = max_abs;
        self.capacity = capacity;
        self.n = n;

        let y_hist = &mut self.y_hist[..outputs];
        let u_hist = &mut self.u_hist[..inputs];
        shift_in(y_hist, y);
        shift_in(u_hist, u);

        for (acc, &yk) in self.yy.iter_mut().zip(y_hist.iter()) {
            *acc = acc.plus(A::product(y, yk));
        }
        for (k, &uk) in u_hist.iter().enumerate() {
            self.uu[k] = self.uu[k].plus(A::product(u, uk));
            self.yu[k] = self.yu[k].plus(A::product(y, uk));
        }
        for (acc, &yk) in self.uy.iter_mut().zip(y_hist[1..].iter()) {
            *acc = acc.plus(A::product(u, yk));
        }
        self.sum_y = self.sum_y.plus(A::widen(y));
        self.sum_u = self.sum_u.plus(A::widen(u));
        Ok(())
    }

    /// Diagnostics only (`scripts/avr-arith-check`): the exact entry of output lags `i`, `j`.
    #[doc(hidden)]
    pub fn output_lag_entry(&self, i: u8, j: u8) -> A {
        self.entry(Col::Y(i), Col::Y(j))
    }

    /// Diagnostics only: the exact entry of input lag `i` and output lag `j`.
    #[doc(hidden)]
    pub fn input_output_entry(&self, i: u8, j: u8) -> A {
        self.entry(Col::U(i), Col::Y(j))
    }

    /// `Σ_{t=1..N} a_t b_t` for two columns of the zero-padded lag matrix.
    pub(crate) fn entry(&self, a: Col, b: Col) -> A {
        match (a, b) {
            (Col::One, Col::One) => A::widen_count(self.n),
            (Col::One, c) | (c, Col::One) => self.column_sum(c),
            // Each arm subtracts `Σ_{m<i} a_{N-m} b_{N-m-k}`, what the running correlation at
            // lag `k` holds beyond the rows where the earlier column is still inside the
            // record ([`tail`]).
            (Col::Y(i), Col::Y(j)) => {
                let (i, k) = lag_pair(i, j);
                let tail = tail::<A>(&self.y_hist, &self.y_hist, i, k);
                self.yy.get(k).copied().unwrap_or_default().minus(tail)
            }
            (Col::U(i), Col::U(j)) => {
                let (i, k) = lag_pair(i, j);
                let tail = tail::<A>(&self.u_hist, &self.u_hist, i, k);
                self.uu.get(k).copied().unwrap_or_default().minus(tail)
            }
            (Col::Y(i), Col::U(j)) | (Col::U(j), Col::Y(i)) => {
                let (i, j) = (usize::from(i), usize::from(j));
                if i <= j {
                    // Σ y_s u_{s-k}, truncated: the output lag is the earlier column.
                    let k = j - i;
                    let tail = tail::<A>(&self.y_hist, &self.u_hist, i, k);
                    self.yu.get(k).copied().unwrap_or_default().minus(tail)
                } else {
                    // Σ u_s y_{s-k}, truncated: the input lag is the earlier column.
                    let k = i - j;
                    let tail = tail::<A>(&self.u_hist, &self.y_hist, j, k);
                    self.uy.get(k - 1).copied().unwrap_or_default().minus(tail)
                }
            }
        }
    }

    /// `Σ_{t=1..N} c_t` for a lag column `c`.
    fn column_sum(&self, c: Col) -> A {
        let (sum, hist, lag): (A, &[A::Sample], u8) = match c {
            Col::Y(k) => (self.sum_y, &self.y_hist, k),
            Col::U(k) => (self.sum_u, &self.u_hist, k),
            Col::One => return A::widen_count(self.n),
        };
        let mut tail = A::default();
        for &s in hist.iter().take(usize::from(lag)) {
            tail = tail.plus(A::widen(s));
        }
        sum.minus(tail)
    }

    /// Forms the solve-time statistics in physical units: every entry of the lag Gram
    /// scaled by `scale`, with the always-present column `y_{t-1}` eliminated exactly
    /// (see [`Normal`]).
    ///
    /// Errors: [`Error::TooShort`] below 2 samples, [`Error::NotExcited`] when the
    /// input or output is constant, [`Error::NonFinite`] for a non-finite or zero
    /// scale, [`Error::Overflow`] when a value leaves the range of `T`.
    // Inlined so that no call passes the 16-byte `Scale` plus a return pointer: on AVR such
    // calls spill arguments to the stack, which the current backend miscompiles.
    #[inline(always)]
    pub fn normal<T: Real>(&self, scale: Scale) -> Result<Normal<T>> {
        let mut out = Normal::empty();
        self.normal_into(&scale, &mut out)?;
        Ok(out)
    }

    /// [`Gram::normal`] into existing storage: no 840-byte (`f32`) temporary and copy on
    /// the stack, which matters on an 8 KB MCU. On error `out` is left empty. `scale` is
    /// taken by reference: on AVR, arguments that spill to the stack are miscompiled by the
    /// current backend (found with `scripts/avr-arith-check`).
    ///
    /// Never inlined: inlined into the ATmega2560's search, its locals widened that large
    /// frame, whose offsets beyond 63 bytes each cost an address computation (−602 B of
    /// flash, −26 B of stack out of line).
    #[inline(never)]
    pub fn normal_into<T: Real>(&self, scale: &Scale, normal: &mut Normal<T>) -> Result<()> {
        fill_normal(self, scale, normal)
    }
}

/// What [`fill_normal`] reads from a set of statistics: the number of regression rows, the
/// excitation check and the exact entries of the lag Gram over those rows.
trait Rows<A: Accumulator> {
    /// Regression rows `N`.
    fn rows(&self) -> u32;
    /// `true` when the input or the output is constant over the rows.
    fn constant(&self) -> bool;
    /// `Σ y_t²` over the rows (for the rounding level).
    fn y_energy(&self) -> A;
    /// `Σ a_t b_t` over the rows.
    fn sum(&self, a: Col, b: Col) -> A;
}

impl<A: Accumulator> Rows<A> for Gram<A> {
    #[inline(always)]
    fn rows(&self) -> u32 {
        self.n
    }
    #[inline(always)]
    fn constant(&self) -> bool {
        A::is_constant(self.n, self.sum_u, self.uu[0])
            || A::is_constant(self.n, self.sum_y, self.yy[0])
    }
    #[inline(always)]
    fn y_energy(&self) -> A {
        self.yy[0]
    }
    #[inline(always)]
    fn sum(&self, a: Col, b: Col) -> A {
        self.entry(a, b)
    }
}

/// `Σ_{m<n} a_m b_{m+k}` over two lag histories (most recent sample first): the edge terms
/// a running correlation at lag `k` holds beyond the rows of an entry (see the module docs).
///
/// One function for the four history pairs of [`Gram::entry`]. Its arguments (two slices, two
/// counts: 12 bytes) fit in the AVR argument registers: earlier shared forms of this loop were
/// miscompiled on the ATmega2560 (the tail came out zero, or the wrong history was read), the
/// pattern of arguments passed on the stack, which that build reads one byte off (see
/// `wide.rs`); `scripts/avr-arith-check` compares the entries with the host's.
fn tail<A: Accumulator>(a: &[A::Sample], b: &[A::Sample], n: usize, k: usize) -> A {
    let mut sum = A::default();
    for m in 0..n {
        if let (Some(&x), Some(&y)) = (a.get(m), b.get(m + k)) {
            sum = sum.plus(A::product(x, y));
        }
    }
    sum
}

/// The body of [`Gram::normal_into`] for any [`Rows`] (inlined into each caller: the
/// device's path is the plain [`Gram`]'s, unchanged).
#[inline(always)]
fn fill_normal<A: Accumulator, T: Real, S: Rows<A>>(
    src: &S,
    scale: &Scale,
    normal: &mut Normal<T>,
) -> Result<()> {
    normal.clear();
    if !(scale.u.is_finite() && scale.y.is_finite()) || scale.u == 0.0 || scale.y == 0.0 {
        return Err(Error::NonFinite);
    }
    if src.rows() < 2 {
        return Err(Error::TooShort {
            needed: 2,
            have: src.rows(),
        });
    }
    if src.constant() {
        return Err(Error::NotExcited);
    }
    let s11 = src.sum(Col::Y(1), Col::Y(1));
    if s11.is_zero() {
        return Err(Error::NotExcited);
    }
    let col_scale = |c: Col| -> T {
        match c {
            Col::Y(_) => T::from_f64(scale.y),
            Col::U(_) => T::from_f64(scale.u),
            Col::One => T::ONE,
        }
    };
    let sy = T::from_f64(scale.y);
    normal.n = src.rows();
    normal.s11 = s11.to_real::<T>() * sy * sy;
    // In T, not f64: no software doubles on the device (the integer path gives 0).
    normal.y_rounding = T::from_f64(A::rounding(src.rows(), src.y_energy())) * sy * sy;
    let mut s_a1 = [A::default(); N_OTHER];
    for idx in 0..N_OTHER {
        let c = other(idx);
        s_a1[idx] = src.sum(c, Col::Y(1));
        normal.r[idx] = s_a1[idx].to_real::<T>() * col_scale(c) * sy;
    }
    for a in 0..N_OTHER {
        let ca = other(a);
        for b in 0..=a {
            let cb = other(b);
            let sab = src.sum(ca, cb);
            let schur: T = A::schur(&s11, &sab, &s_a1[a], &s_a1[b])?;
            normal.set_schur(a, b, schur * col_scale(ca) * col_scale(cb));
        }
    }
    if let Err(e) = normal.check_finite() {
        normal.clear();
        return Err(e);
    }
    Ok(())
}

/// Statistics from measured initial conditions: the first `m` samples of a record only fill
/// the lag history; the regression rows are `t = m+1..N`, every lag of every structure with
/// `max(p, d + q − 1) ≤ m` taken from measured samples (no zero history of eq. 6). With the
/// same `m` for every candidate of a search ([`crate::Grid::longest_lag`]) all candidates
/// are fitted and scored on the same rows, as MATLAB `arx` and SysIdentPy do.
///
/// Exact and in constant memory: the first `m` rows of the zero-padded matrix of eq. (6) are
/// exactly the rows of the zero-padded matrix of the first `m` samples alone, so every entry
/// over rows `m+1..N` is the entry of the whole record's [`Gram`] minus the entry of the
/// first `m` samples' [`Gram`] (both kept, two accumulators; exact in `i64`). `m = 0` gives
/// the zero-history statistics of [`Gram`]. Not used by the firmware (its statistics are the
/// plain [`Gram`]'s).
///
/// # Example
/// ```
/// use ridge_core::{MeasuredGram, Offset, Scale, Structure};
/// let mut g = MeasuredGram::<f64>::new(3);
/// let mut y1 = 5.0; // the record starts at an operating point
/// for t in 0..200 {
///     let u = if (t / 9) % 2 == 0 { 3.0 } else { 3.5 } + (t % 5) as f64 * 0.01;
///     let y = 0.8 * y1 + 0.25 * u + 0.25; // y settles around 5.1 .. 5.5
///     g.push(u, y)?;
///     y1 = y;
/// }
/// let normal = g.normal::<f64>(Scale::UNIT)?;
/// assert_eq!(normal.samples(), 197); // rows 4..=200
/// let sys = normal.system(Structure::new(1, 1, 0)?, Offset::Intercept)?;
/// let w = sys.factor(0.0)?.solution(); // internal order: y(t-1), 1, u(t)
/// assert!((w[0] - 0.8).abs() < 1e-9 && (w[1] - 0.25).abs() < 1e-9 && (w[2] - 0.25).abs() < 1e-9);
/// # Ok::<(), ridge_core::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredGram<A: Accumulator> {
    all: Gram<A>,
    head: Gram<A>,
    m: u32,
    /// Output lags kept: `0..outputs` (`P_MAX + 1`: all).
    outputs: usize,
    /// Input lags kept: `0..inputs` (`L_MAX`: all).
    inputs: usize,
}

impl<A: Accumulator> MeasuredGram<A> {
    /// Empty statistics whose first `m` samples will be initial conditions only.
    pub fn new(m: u32) -> Self {
        MeasuredGram {
            all: Gram::new(),
            head: Gram::new(),
            m,
            outputs: P_MAX + 1,
            inputs: L_MAX,
        }
    }

    /// [`MeasuredGram::new`] keeping only the lags the candidates of `grid` use — output lags
    /// up to `p_max`, input lags up to `d_max + q_max − 1` — so that a sample costs the
    /// products of those lags rather than of the maxima (on the host's maxima 12/12/12 and
    /// the default grid 6/6/6: 37 instead of 73). The statistics of every structure of
    /// `grid` are exactly those of [`MeasuredGram::new`] (the same sums in the same order);
    /// the entries of other lags in [`MeasuredGram::normal`] are zero, so a structure outside
    /// `grid` is not fitted on them (a zero column: [`Error::NotPositiveDefinite`]).
    pub fn for_grid(m: u32, grid: &Grid) -> Self {
        let mut g = Self::new(m);
        g.outputs = (usize::from(grid.p.max) + 1).min(P_MAX + 1);
        g.inputs = (usize::from(grid.d.max) + usize::from(grid.q.max)).min(L_MAX);
        g
    }

    /// `true` when column `c` is kept (see [`MeasuredGram::for_grid`]).
    fn keeps(&self, c: Col) -> bool {
        match c {
            Col::Y(k) => usize::from(k) < self.outputs,
            Col::U(k) => usize::from(k) < self.inputs,
            Col::One => true,
        }
    }

    /// The number `m` of initial samples that contribute no row.
    pub fn initial(&self) -> u32 {
        self.m
    }

    /// Samples pushed (`N`, initial ones included).
    pub fn len(&self) -> u32 {
        self.all.len()
    }

    /// `true` before the first sample.
    pub fn is_empty(&self) -> bool {
        self.all.is_empty()
    }

    /// Regression rows: `N − m` (0 while `N ≤ m`).
    pub fn rows(&self) -> u32 {
        self.all.len() - self.head.len()
    }

    /// The zero-history statistics of the whole record (eq. 6); made by
    /// [`MeasuredGram::for_grid`], only its entries of the grid's lags are kept up to date.
    pub fn all(&self) -> &Gram<A> {
        &self.all
    }

    /// Adds the sample `(u_t, y_t)` (see [`Gram::push`]). Errors as [`Gram::push`]; on error
    /// the statistics are unchanged.
    pub fn push(&mut self, u: A::Sample, y: A::Sample) -> Result<()> {
        let (outputs, inputs) = (self.outputs, self.inputs);
        self.all.push_lags(u, y, outputs, inputs)?;
        if self.head.len() < self.m {
            // Cannot fail: the same samples, fewer of them, were just accepted by `all`.
            self.head.push_lags(u, y, outputs, inputs)?;
        }
        Ok(())
    }

    /// The solve-time statistics of rows `m+1..N` (see [`Gram::normal`]; `N` there is the
    /// number of rows, [`MeasuredGram::rows`]). Errors as [`Gram::normal`]:
    /// [`Error::TooShort`] below 2 rows, [`Error::NotExcited`] when the input or output is
    /// constant over the rows.
    pub fn normal<T: Real>(&self, scale: Scale) -> Result<Normal<T>> {
        let mut out = Normal::empty();
        self.normal_into(&scale, &mut out)?;
        Ok(out)
    }

    /// [`MeasuredGram::normal`] into existing storage; on error `out` is left empty.
    pub fn normal_into<T: Real>(&self, scale: &Scale, normal: &mut Normal<T>) -> Result<()> {
        fill_normal(self, scale, normal)
    }
}

impl<A: Accumulator> Rows<A> for MeasuredGram<A> {
    fn rows(&self) -> u32 {
        MeasuredGram::rows(self)
    }
    fn constant(&self) -> bool {
        let (a, h) = (&self.all, &self.head);
        let n = self.rows();
        A::is_constant(n, a.sum_u.minus(h.sum_u), a.uu[0].minus(h.uu[0]))
            || A::is_constant(n, a.sum_y.minus(h.sum_y), a.yy[0].minus(h.yy[0]))
    }
    fn y_energy(&self) -> A {
        // The rounding of the difference is that of the larger sum.
        self.all.yy[0]
    }
    fn sum(&self, a: Col, b: Col) -> A {
        if !(self.keeps(a) && self.keeps(b)) {
            return A::default();
        }
        self.all.entry(a, b).minus(self.head.entry(a, b))
    }
}

/// `h[k] ← h[k − 1]`, `h[0] ← v`: an unrolled shift instead of a `memmove` call.
#[inline(always)]
fn shift_in<S: Copy>(h: &mut [S], v: S) {
    for k in (1..h.len()).rev() {
        h[k] = h[k - 1];
    }
    if let Some(first) = h.first_mut() {
        *first = v;
    }
}

/// `(earlier lag, lag difference)` of two lags of the same signal.
fn lag_pair(i: u8, j: u8) -> (usize, usize) {
    let (lo, hi) = if i <= j { (i, j) } else { (j, i) };
    (usize::from(lo), usize::from(hi - lo))
}

#[cfg(test)]
mod tests {
    use super::Accumulator;

    /// The integer capacity is safe (`capacity · max² ≤ i64::MAX`, checked in 128 bits) and
    /// at most a factor 8 below the exact bound `⌊i64::MAX / max²⌋` (or the whole `u32`
    /// range), for every magnitude up to 2¹⁷ and both sides of every power of two up to 2³¹
    /// (the largest `i32` magnitude).
    #[test]
    fn integer_capacity_is_safe_and_within_a_factor_8() {
        let powers = (0..=31).flat_map(|k| {
            let p = 1i64 << k;
            [p - 1, p, p + 1]
        });
        // Samples are i32: magnitudes up to 2³¹.
        for m in (0..=1i64 << 17).chain(powers.filter(|&m| m <= 1 << 31)) {
            let cap = i128::from(<i64 as Accumulator>::capacity(m));
            let sq = i128::from(m) * i128::from(m);
            let max = i128::from(i64::MAX);
            assert!(cap * sq <= max, "max {m}: capacity {cap} overflows");
            let exact = if sq == 0 { max } else { max / sq };
            assert!(
                cap == i128::from(u32::MAX) || 8 * cap > exact,
                "max {m}: capacity {cap}, exact {exact}"
            );
        }
    }
}
