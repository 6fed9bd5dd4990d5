//! [`Rst`]: a controller in the polynomial form
//! `R(q⁻¹) u_{t+1} = T(q⁻¹) r_{t+1} − S(q⁻¹) y_t`, and [`Controller`]: one running with duty
//! limits, a duty rate limit, anti-windup and a bumpless start.

use crate::model::{ring_back, ring_dot};
use crate::real::Real;
use crate::{D_MAX, P_MAX, Q_MAX};

/// Coefficients of `R`: degree `d + q ≤ 12` for the pole-placement design (integrator included).
pub const R_LEN: usize = D_MAX + Q_MAX + 1;
/// Coefficients of `S` (degree `p ≤ 6`) and of `T`.
pub const S_LEN: usize = P_MAX + 1;

/// The three polynomials of a two-degree-of-freedom controller, in the backward shift `q⁻¹`
/// (coefficients in ascending powers, `R` monic):
///
/// `R(q⁻¹) u_{t+1} = T(q⁻¹) r_{t+1} − S(q⁻¹) y_t`
///
/// `u_{t+1}` is the input for the interval that ends with the reading `y_{t+1}`, computed from
/// readings up to `y_t`; `r` is the setpoint. With a plant `A y = q^{−d} B u` the closed loop
/// is `P = A R + q^{−d−1} B S`. Integral action: `R(1) = 0`; unit static gain: `T(1) = S(1)`.
/// Units are the model's (here: duty fraction 0..1 for `u`, slm for `y` and `r`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rst<T: Real> {
    r: [T; R_LEN],
    s: [T; S_LEN],
    /// The anti-windup observer polynomial `A_o` (monic, stable).
    ao: [T; S_LEN],
    /// `T = t₀ A_o`.
    t0: T,
    /// The setpoint's reference model ([`set_reference`](Self::set_reference)) as the
    /// running controller uses it: `(1 − γ, t₀ α / (1 − α))`; without one `(1, 0)`, which
    /// passes the setpoint through unchanged.
    reference: [T; 2],
    nr: u8,
    ns: u8,
    nao: u8,
}

/// Coefficients of a polynomial computed on demand ([`Rst::t`]), a slice through `Deref`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients<T> {
    c: [T; S_LEN],
    n: u8,
}

impl<T> core::ops::Deref for Coefficients<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        self.c.get(..usize::from(self.n)).unwrap_or(&[])
    }
}

/// Why an [`Rst`] cannot be built from given coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RstError {
    /// A polynomial is empty or longer than its capacity ([`R_LEN`], [`S_LEN`]).
    Size,
    /// `R` or `A_o` is not monic (first coefficient ≠ 1).
    NotMonic,
    /// A coefficient is NaN or ±∞.
    NonFinite,
}

impl<T: Real> Rst<T> {
    /// The controller with these coefficients (ascending powers of `q⁻¹`), the anti-windup
    /// observer polynomial `ao` (`A_o`, monic and stable: the dynamics the controller's state
    /// follows while its output is limited, see [`Controller`]) and `T = t0 · A_o`: the
    /// setpoint enters through the observer polynomial, so that it excites only the designed
    /// setpoint response (the observer's poles cancel), and the running controller needs one
    /// product for the setpoint instead of `deg A_o + 1`. `r[0]` and `ao[0]` must be 1.
    pub fn new(r: &[T], s: &[T], t0: T, ao: &[T]) -> Result<Self, RstError> {
        let sizes_ok = |x: &[T], cap: usize| !x.is_empty() && x.len() <= cap;
        if !(sizes_ok(r, R_LEN) && sizes_ok(s, S_LEN) && sizes_ok(ao, S_LEN)) {
            return Err(RstError::Size);
        }
        if r[0] != T::ONE || ao[0] != T::ONE {
            return Err(RstError::NotMonic);
        }
        let mut out = Rst {
            r: [T::ZERO; R_LEN],
            s: [T::ZERO; S_LEN],
            ao: [T::ZERO; S_LEN],
            t0,
            reference: [T::ONE, T::ZERO],
            nr: r.len() as u8,
            ns: s.len() as u8,
            nao: ao.len() as u8,
        };
        // The lengths were checked above.
        out.r[..r.len()].copy_from_slice(r);
        out.s[..s.len()].copy_from_slice(s);
        out.ao[..ao.len()].copy_from_slice(ao);
        let all = out.r.iter().chain(&out.s).chain(&out.ao);
        if !t0.is_finite() || all.clone().any(|x| !x.is_finite()) {
            return Err(RstError::NonFinite);
        }
        Ok(out)
    }

    /// Shapes the setpoint by a reference model: the [`Controller`] feeds `T` with
    /// `(r_m,t+1 − α r_m,t) / (1 − α)` instead of `r_{t+1}`, where
    /// `r_m,t+1 = γ r_m,t + (1 − γ) r_{t+1}`. For a design whose setpoint response is
    /// `q^{−d−1} (B / B(1)) (1 − α) / (1 − α q⁻¹)` (pole placement, [`design`](super::design())),
    /// this cancels the pole `α` and puts `γ` in its place: the flow follows a first-order
    /// reference with pole `γ` after the loop delay, at any speed of the regulation loop (`R`
    /// and `S`, the closed-loop poles and the margin are unchanged). Refused, and nothing
    /// changed ([`RstError::NonFinite`]), unless `0 ≤ α < 1` and `0 ≤ γ < 1`.
    pub fn set_reference(&mut self, alpha: T, gamma: T) -> Result<(), RstError> {
        // `α / (1 − α)` is finite and at least 0 exactly for `0 ≤ α < 1`; NaN fails every
        // comparison.
        let ratio = alpha / (T::ONE - alpha);
        if !(gamma >= T::ZERO && gamma < T::ONE && ratio >= T::ZERO && ratio.is_finite()) {
            return Err(RstError::NonFinite);
        }
        self.reference = [T::ONE - gamma, self.t0 * ratio];
        Ok(())
    }

    /// The reference model's pole `γ`, `None` without one (the setpoint is used as given;
    /// also for `γ = α = 0`, whose reference model passes the setpoint through unchanged).
    pub fn reference_pole(&self) -> Option<T> {
        let [gain, lead] = self.reference;
        (gain != T::ONE || lead != T::ZERO).then(|| T::ONE - gain)
    }

    /// `R` (monic), ascending powers of `q⁻¹`.
    pub fn r(&self) -> &[T] {
        self.r.get(..usize::from(self.nr)).unwrap_or(&[])
    }

    /// `S`, ascending powers of `q⁻¹`.
    pub fn s(&self) -> &[T] {
        self.s.get(..usize::from(self.ns)).unwrap_or(&[])
    }

    /// `T = t₀ A_o`, ascending powers of `q⁻¹` (computed: only `t₀` and `A_o` are stored,
    /// which the ATmega2560's design and console code need 0.14 KB less flash for).
    pub fn t(&self) -> Coefficients<T> {
        let mut c = [T::ZERO; S_LEN];
        for (t, &a) in c.iter_mut().zip(self.ao()) {
            *t = self.t0 * a;
        }
        Coefficients { c, n: self.nao }
    }

    /// `t₀`: `T = t₀ A_o`.
    pub fn t0(&self) -> T {
        self.t0
    }

    /// The anti-windup observer polynomial `A_o` (monic), ascending powers of `q⁻¹`.
    pub fn ao(&self) -> &[T] {
        self.ao.get(..usize::from(self.nao)).unwrap_or(&[])
    }
}

/// Limits of the controller's output, in the input's units (duty fraction 0..1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits<T> {
    /// Smallest output.
    pub min: T,
    /// Largest output.
    pub max: T,
    /// Largest change of the output from one tick to the next (rate limit).
    pub max_step: T,
}

/// An [`Rst`] controller running: its past inputs, outputs and setpoints, and its limits.
///
/// - **Anti-windup** (Åström and Wittenmark, *Computer-Controlled Systems*, the observer form):
///   `A_o v = T r − S y + (A_o − R) û`, `û = sat(v)`: the controller's state is driven by the
///   inputs actually applied (`û`, after the limits and the rate limit) and, while the output
///   is limited, follows the stable dynamics of `A_o` instead of integrating the error. Without
///   limiting `v = û` and this is `R u = T r − S y`. With `A_o = 1` it is the plain "past
///   applied inputs" form; the design's observer polynomial recovers best (measured on the
///   default pump model after 2 s at the duty limit: no undershoot and 18 samples to settle,
///   against 14 slm of undershoot and 50 samples with `A_o = 1`).
/// - **Rate limit**: each output moves at most [`Limits::max_step`] from the previous applied
///   one.
/// - **Bumpless start** ([`start`](Self::start)): the histories are filled with the operating
///   point `(u₀, y₀)` and the setpoint with `y₀`, which is an equilibrium of the loop
///   (`R(1) = 0`, `T(1) = S(1)`): the first output is `u₀` unless the setpoint or the flow
///   moved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Controller<T: Real> {
    rst: Rst<T>,
    limits: Limits<T>,
    /// `R − A_o` from its coefficient 1 on: the weights of the past applied inputs
    /// `u_t, u_{t−1}, …` in the observer form (one product per input instead of two).
    ru: [T; R_LEN],
    nru: u8,
    /// Applied inputs, a ring with the newest (`u_t`) at `hu`, older ones at `hu + 1, …`
    /// (wrapping). Rings instead of shifted arrays: on the ATmega2560 shifting the histories
    /// cost ~700 cycles a tick, a ring index a few per coefficient.
    u: [T; R_LEN],
    /// Readings (`y_t` at `hs` after a step), a ring sharing `hs` with `z`.
    y: [T; S_LEN],
    /// `z_t = t₀ r'_t − v_t` (`z_t` at `hs` after a step), with `r'_t` the setpoint the step
    /// was given, through the reference model if there is one, and `v_t` its unlimited
    /// output: `T r' − (A_o − 1) v` is then `t₀ r'_{t+1} + Σ_{k≥1} a_k z_{t+1−k}`, one product
    /// per observer coefficient.
    z: [T; S_LEN],
    hu: u8,
    hs: u8,
    /// The reference model's output `r_m,t` (the setpoint itself without a reference model).
    rm: T,
    /// What [`output`](Self::output) computed for [`commit`](Self::commit): `t₀ r'_{t+1}`
    /// and the output `v_{t+1}` as the observer form records it (`u_t` when it was not finite).
    pending: [T; 2],
}

impl<T: Real> Controller<T> {
    /// A controller with all histories at zero (call [`start`](Self::start) before use).
    pub fn new(rst: Rst<T>, limits: Limits<T>) -> Self {
        let mut ru = [T::ZERO; R_LEN];
        let n = rst.r().len().max(rst.ao().len());
        for (k, x) in ru.iter_mut().enumerate().take(n.saturating_sub(1)) {
            let at = |p: &[T]| p.get(k + 1).copied().unwrap_or(T::ZERO);
            *x = at(rst.r()) - at(rst.ao());
        }
        Controller {
            rst,
            limits,
            ru,
            // ≤ max(R_LEN, S_LEN) − 1 = 12.
            nru: n.saturating_sub(1) as u8,
            u: [T::ZERO; R_LEN],
            y: [T::ZERO; S_LEN],
            z: [T::ZERO; S_LEN],
            hu: 0,
            hs: 0,
            rm: T::ZERO,
            pending: [T::ZERO; 2],
        }
    }

    /// The polynomials.
    pub fn rst(&self) -> &Rst<T> {
        &self.rst
    }

    /// The output limits.
    pub fn limits(&self) -> &Limits<T> {
        &self.limits
    }

    /// Bumpless start at the operating point: input `u0` applied now, reading `y0`, setpoint
    /// history (and the reference model's output) `y0`.
    pub fn start(&mut self, u0: T, y0: T) {
        self.u = [u0; R_LEN];
        self.y = [y0; S_LEN];
        self.z = [self.rst.t0 * y0 - u0; S_LEN];
        self.hu = 0;
        self.hs = 0;
        self.rm = y0;
    }

    /// The input applied last (`u_t`).
    pub fn last(&self) -> T {
        self.u.get(usize::from(self.hu)).copied().unwrap_or(T::ZERO)
    }

    /// One tick: takes the reading `y_t` and the setpoint `r_{t+1}` for the coming interval,
    /// returns `u_{t+1}` within the limits and the rate limit (a NaN result holds `u_t`). With
    /// a reference model ([`Rst::set_reference`]) the setpoint moves the model's output first.
    ///
    /// The same as [`output`](Self::output), the limits, then [`commit`](Self::commit) of the
    /// limited value.
    pub fn step(&mut self, r_next: T, y: T) -> T {
        let last = self.last();
        let v = self.output(r_next, y);
        let applied = if v.is_finite() {
            let lo = max(self.limits.min, last - self.limits.max_step);
            let hi = min(self.limits.max, last + self.limits.max_step);
            min(max(v, lo), hi)
        } else {
            last
        };
        self.commit(applied);
        applied
    }

    /// First half of a tick, for a caller that limits the output itself (e.g. in other units,
    /// after a static map): takes the reading `y_t` and the setpoint `r_{t+1}`, returns the
    /// controller's unlimited output `v_{t+1}` (NaN or ±∞ when it is not finite: apply `u_t`
    /// again). [`commit`](Self::commit) must follow, with the input actually applied, before
    /// the next `output`. The reference model holds while [`last`](Self::last) sits at the
    /// limit the setpoint pulls it towards ([`Limits::min`], [`Limits::max`]).
    pub fn output(&mut self, r_next: T, y: T) -> T {
        let c = &self.rst;
        // t₀ times the setpoint `T` sees, (r_m,t+1 − α r_m,t) / (1 − α) (r_{t+1} itself
        // without a reference model), as t₀ r_m,t+1 + t₀ α / (1 − α) · (r_m,t+1 − r_m,t).
        let [gain, lead] = c.reference;
        // The reference model (the setpoint) holds while the output sits at the limit the
        // setpoint pulls it towards: otherwise its state runs ahead of what the plant can
        // follow and the flow lags it long after the output comes off the limit (measured on
        // the default pump after 2 s at the duty limit: 60 samples to settle instead of 36 + a
        // few).
        let last = self.last();
        let up = r_next > self.rm;
        let held = (up && last >= self.limits.max) || (!up && last <= self.limits.min);
        let moved = if held {
            T::ZERO
        } else {
            gain * (r_next - self.rm)
        };
        self.rm += moved;
        let tr = c.t0 * self.rm + lead * moved;
        // The previous step's newest entries: u_t at `hu`, y_t and z_t at `hs`.
        let (hu, hs_old) = (usize::from(self.hu), usize::from(self.hs));
        let hs = ring_back(hs_old, S_LEN);
        if let Some(yy) = self.y.get_mut(hs) {
            *yy = y;
        }
        // T r' − S y + (A_o − R) û − (A_o − 1) v with T = t₀ A_o, as
        // t₀ r'_{t+1} − S y − (R − A_o)·(u_t, u_{t−1}, …) + (A_o − 1)·(z_t, z_{t−1}, …).
        let ru = self.ru.get(..usize::from(self.nru)).unwrap_or(&[]);
        let ao = c.ao().get(1..).unwrap_or(&[]);
        let v = tr - ring_dot(c.s(), &self.y, hs) - ring_dot(ru, &self.u, hu)
            + ring_dot(ao, &self.z, hs_old);
        let recorded = if v.is_finite() {
            v
        } else {
            // A non-finite setpoint must not stay in the reference model's state.
            self.rm = y;
            last
        };
        // Below its capacity (7).
        self.hs = hs as u8;
        self.pending = [tr, recorded];
        v
    }

    /// Second half of a tick after [`output`](Self::output): records `applied`, the input
    /// actually applied for the coming interval (the output after the caller's limits; the
    /// controller's state follows it, see the anti-windup above).
    pub fn commit(&mut self, applied: T) {
        let [tr, v] = self.pending;
        let hu = ring_back(usize::from(self.hu), R_LEN);
        if let (Some(zz), Some(uu)) = (self.z.get_mut(usize::from(self.hs)), self.u.get_mut(hu)) {
            *zz = tr - v;
            *uu = applied;
        }
        // Below its capacity (13).
        self.hu = hu as u8;
    }
}

fn max<T: Real>(a: T, b: T) -> T {
    if b > a {
        b
    } else {
        a
    }
}

fn min<T: Real>(a: T, b: T) -> T {
    if b < a {
        b
    } else {
        a
    }
}
