//! Blower pump on one PWM channel ([`embedded_hal::pwm::SetDutyCycle`]).
//!
//! Duty is commanded in units of 1/10 000 of full scale ([`DUTY_FULL_SCALE`]`= 10 000` = 100 %),
//! independent of the timer's resolution, and mapped to the channel's
//! [`max_duty_cycle`](SetDutyCycle::max_duty_cycle) with integer math (rounded to nearest).
//!
//! [`Pump`] adds what a blower needs between the controller and the timer:
//!
//! - **Limits** `min_duty..=max_duty`: a non-zero command is clamped into that band, while 0
//!   (stop) is always allowed. The applied duty is therefore always 0 or inside the band (a
//!   minimum keeps a BLDC out of the duty range where it stalls).
//! - **Ramp limit**: the applied duty moves towards the command by at most
//!   [`ramp_limit`](Pump::ramp_limit) duty units per call of [`set`](Pump::set) or
//!   [`tick`](Pump::tick), i.e. per 10 ms tick of the 100 Hz loop.
//! - [`stop`](Pump::stop) writes 0 at once, bypassing the ramp.
//!
//! # Example
//!
//! ```
//! # use embedded_hal_mock::eh1::pwm::{Mock, Transaction};
//! use ridge_pump_firmware::pump::Pump;
//!
//! # let expectations = [
//! #     Transaction::max_duty_cycle(799), Transaction::set_duty_cycle(0),   // new()
//! #     Transaction::max_duty_cycle(799), Transaction::set_duty_cycle(160), // 2000
//! #     Transaction::max_duty_cycle(799), Transaction::set_duty_cycle(200), // 2500
//! #     Transaction::max_duty_cycle(799), Transaction::set_duty_cycle(0),   // stop()
//! # ];
//! # let pwm = Mock::new(&expectations);
//! let mut pump = Pump::new(pwm)?; // writes 0 %
//! pump.set_limits(2_000, 8_000); // 20 % .. 80 % while running
//! pump.set_ramp_limit(500); // at most 5 % per 10 ms tick
//! // From standstill the pump starts at the minimum duty...
//! assert_eq!(pump.set(3_000)?, 2_000);
//! // ...then ramps towards the command, one step per tick.
//! assert_eq!(pump.tick()?, 2_500);
//! assert_eq!(pump.commanded(), 3_000);
//! pump.stop()?; // 0 at once
//! assert_eq!(pump.applied(), 0);
//! # pump.release().done();
//! # Ok::<(), ridge_pump_firmware::pump::Error<embedded_hal_mock::eh1::MockError>>(())
//! ```

use embedded_hal::pwm::SetDutyCycle;

use crate::units::DUTY_FULL_SCALE;

/// A ramp limit this large (or larger) means "no ramp limit": one step covers the whole scale.
pub const NO_RAMP_LIMIT: u16 = DUTY_FULL_SCALE;

/// Errors of the pump driver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The PWM channel refused a duty cycle.
    Pwm(E),
}

/// Maps a duty in command units (0..=[`DUTY_FULL_SCALE`], larger values are treated as full
/// scale) to timer counts `0..=max_duty_cycle`, rounded to the nearest count (halves up).
///
/// Integer math only: `(duty · max + 5000) / 10000` in `u32`, which cannot overflow for any
/// `max_duty_cycle` up to 65535.
///
/// ```
/// use ridge_pump_firmware::pump::duty_to_counts;
/// assert_eq!(duty_to_counts(5_000, 799), 400); // 399.5 rounds up
/// assert_eq!(duty_to_counts(10_000, 65_535), 65_535);
/// assert_eq!(duty_to_counts(1, 255), 0); // 0.0255 rounds down
/// ```
pub fn duty_to_counts(duty: u16, max_duty_cycle: u16) -> u16 {
    let duty = u32::from(duty.min(DUTY_FULL_SCALE));
    let max = u32::from(max_duty_cycle);
    let full = u32::from(DUTY_FULL_SCALE);
    // ≤ 10 000 · 65 535 + 5 000 = 655 355 000 < 2³²; the quotient is ≤ max.
    let counts = (duty * max + full / 2) / full;
    u16::try_from(counts).unwrap_or(max_duty_cycle)
}

/// A pump (blower) driven by one PWM channel, with duty limits and a ramp-rate limit.
///
/// All duties are in command units of 1/10 000 of full scale (see [`DUTY_FULL_SCALE`]).
#[derive(Debug)]
pub struct Pump<P> {
    pwm: P,
    min_duty: u16,
    max_duty: u16,
    ramp_limit: u16,
    commanded: u16,
    applied: u16,
}

impl<P: SetDutyCycle> Pump<P> {
    /// Takes the PWM channel and writes duty 0 to it, so that the pump starts stopped.
    ///
    /// Defaults: limits `0..=DUTY_FULL_SCALE` (no clamping) and no ramp limit.
    pub fn new(pwm: P) -> Result<Self, Error<P::Error>> {
        let mut pump = Pump {
            pwm,
            min_duty: 0,
            max_duty: DUTY_FULL_SCALE,
            ramp_limit: NO_RAMP_LIMIT,
            commanded: 0,
            applied: 0,
        };
        pump.write(0)?;
        Ok(pump)
    }

    /// Sets the allowed band for a running pump, in duty units: a non-zero command is clamped
    /// into `min_duty..=max_duty`; 0 (stop) is always allowed.
    ///
    /// The values are made consistent rather than rejected: `max_duty` is capped at
    /// [`DUTY_FULL_SCALE`] and `min_duty` at `max_duty`. The current command is re-clamped at
    /// once; the applied duty follows at the next [`set`](Pump::set) or [`tick`](Pump::tick)
    /// (a lower maximum takes effect there without ramping).
    pub fn set_limits(&mut self, min_duty: u16, max_duty: u16) {
        self.max_duty = max_duty.min(DUTY_FULL_SCALE);
        self.min_duty = min_duty.min(self.max_duty);
        self.commanded = self.clamp(self.commanded);
    }

    /// The lower limit of a running pump, in duty units.
    pub fn min_duty(&self) -> u16 {
        self.min_duty
    }

    /// The upper limit, in duty units.
    pub fn max_duty(&self) -> u16 {
        self.max_duty
    }

    /// Sets the largest change of the applied duty per call of [`set`](Pump::set) or
    /// [`tick`](Pump::tick), in duty units per 10 ms tick. [`NO_RAMP_LIMIT`] (or more) disables
    /// the limit; 0 is raised to 1 (a limit of 0 would never move).
    ///
    /// Two steps are exempt so that the applied duty is never strictly between 0 and
    /// [`min_duty`](Pump::min_duty): starting from 0 goes straight to `min_duty`, and ramping
    /// down to 0 goes from the last step at or above `min_duty` straight to 0.
    pub fn set_ramp_limit(&mut self, max_step: u16) {
        self.ramp_limit = max_step.max(1);
    }

    /// The ramp limit, in duty units per call of [`set`](Pump::set) or [`tick`](Pump::tick).
    pub fn ramp_limit(&self) -> u16 {
        self.ramp_limit
    }

    /// Commands a new duty (in duty units; values above [`DUTY_FULL_SCALE`] count as full scale)
    /// and moves the applied duty one ramp step towards it, as [`tick`](Pump::tick) does.
    ///
    /// The command is clamped into the limits first (0 stays 0). Returns the applied duty.
    pub fn set(&mut self, duty: u16) -> Result<u16, Error<P::Error>> {
        self.commanded = self.clamp(duty);
        self.tick()
    }

    /// Moves the applied duty one ramp step towards the command and writes it to the PWM
    /// channel (every call writes, even if the duty did not change). Call once per 10 ms tick.
    ///
    /// Returns the applied duty. On a PWM error the applied duty keeps its previous value.
    pub fn tick(&mut self) -> Result<u16, Error<P::Error>> {
        let next = self.next_step();
        self.write(next)?;
        Ok(self.applied)
    }

    /// Stops the pump: command 0 and write 0 at once, bypassing the ramp limit.
    pub fn stop(&mut self) -> Result<(), Error<P::Error>> {
        self.commanded = 0;
        self.write(0)
    }

    /// The commanded (target) duty after clamping, in duty units.
    pub fn commanded(&self) -> u16 {
        self.commanded
    }

    /// The duty last written to the PWM channel, in duty units.
    pub fn applied(&self) -> u16 {
        self.applied
    }

    /// Gives back the PWM channel (without stopping it: call [`stop`](Pump::stop) first if the
    /// pump should not keep running).
    pub fn release(self) -> P {
        self.pwm
    }

    /// Clamps a command into the limits, keeping 0 (stop).
    fn clamp(&self, duty: u16) -> u16 {
        if duty == 0 {
            0
        } else {
            // Not Ord::clamp: its min > max panic path would be compiled in (min ≤ max holds
            // by set_limits, but the compiler cannot see it).
            duty.max(self.min_duty).min(self.max_duty)
        }
    }

    /// The applied duty after one ramp step towards the command.
    fn next_step(&self) -> u16 {
        let current = self.applied;
        let target = self.commanded;
        let step = if target >= current {
            let up = current.saturating_add((target - current).min(self.ramp_limit));
            if up != 0 && up < self.min_duty {
                // Starting: skip the band where the blower stalls.
                self.min_duty.min(target)
            } else {
                up
            }
        } else {
            let down = current - (current - target).min(self.ramp_limit);
            if down < self.min_duty {
                // target < min_duty here, so target is 0: stop rather than crawl below min.
                target
            } else {
                down
            }
        };
        step.min(self.max_duty)
    }

    /// Writes `duty` (duty units) to the channel and records it as applied on success.
    fn write(&mut self, duty: u16) -> Result<(), Error<P::Error>> {
        let counts = duty_to_counts(duty, self.pwm.max_duty_cycle());
        self.pwm.set_duty_cycle(counts).map_err(Error::Pwm)?;
        self.applied = duty;
        Ok(())
    }
}
