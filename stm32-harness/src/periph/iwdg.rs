//! IWDG, the independent watchdog (RM0383 §15): a 12-bit down-counter clocked by the LSI
//! through a prescaler, reloaded by the key 0xAAAA, resetting the chip when it reaches 0.
//!
//! Modelled:
//! - `IWDG_KR` (§15.4.1): 0xCCCC starts the watchdog (it cannot be stopped but by a reset),
//!   0xAAAA reloads the counter from the reload value, 0x5555 enables writes to PR and RLR,
//!   any other key disables them again (§15.3.5 "Register access protection").
//! - `IWDG_PR` (§15.4.2): divider 4 × 2^PR (PR ≥ 6: 256); `IWDG_RLR` (§15.4.3): 12-bit reload.
//! - `IWDG_SR` (§15.4.4): PVU and RVU are set while a new PR or RLR value is carried into the
//!   watchdog's own (VDD) domain, "up to 5 RC 40 kHz cycles"; until then the counter keeps
//!   using the old value (a reload right after writing RLR reloads the old one). Modelled as
//!   5 LSI periods. A new prescaler changes the counting rate from the moment it arrives; a
//!   new reload value is used from the next reload.
//! - the counter counts down at f_LSI / divider from its reload and the chip resets when it
//!   reaches 0 (§15.3.1), with IWDGRSTF in RCC_CSR (the machine does the reset).
//! - f_LSI is its typical 32 kHz (STM32F411xC/E datasheet DS10314, "LSI oscillator
//!   characteristics": 17–47 kHz). Simplification: the LSI is exact, so the timeout is the
//!   nominal one; a real chip's may differ by −47 %/+88 %.
//! - Simplification: `DBGMCU_APB1_FZ.DBG_IWDG_STOP` has no effect (no debugger halts the core).

use super::{Time, Unmodelled, PS_PER_S};

/// LSI frequency, Hz.
pub const LSI_HZ: u64 = 32_000;
/// Register offsets (§15.4.5, register map).
pub const KR: u32 = 0x00;
/// Prescaler.
pub const PR: u32 = 0x04;
/// Reload.
pub const RLR: u32 = 0x08;
/// Status.
pub const SR: u32 = 0x0C;

/// The watchdog.
#[derive(Clone, Debug)]
pub struct Iwdg {
    /// Values written to PR and RLR.
    pr: u32,
    rlr: u32,
    /// Values in effect, and when the written ones take over.
    pr_active: u32,
    rlr_active: u32,
    pr_update: Option<Time>,
    rlr_update: Option<Time>,
    unlocked: bool,
    /// The counter as of a time: (time, LSI periods left until it reaches 0 at the divider in
    /// effect), `None` while stopped.
    count: Option<(Time, u64)>,
    /// Reloads (feeds) seen, for tests.
    pub feeds: u64,
}

impl Default for Iwdg {
    fn default() -> Self {
        Self::new()
    }
}

fn lsi_period() -> Time {
    PS_PER_S / LSI_HZ
}

impl Iwdg {
    /// At reset: stopped, PR = 0, RLR = 0xFFF.
    pub fn new() -> Self {
        Iwdg {
            pr: 0,
            rlr: 0xFFF,
            pr_active: 0,
            rlr_active: 0xFFF,
            pr_update: None,
            rlr_update: None,
            unlocked: false,
            count: None,
            feeds: 0,
        }
    }

    fn divider(pr: u32) -> u64 {
        4 << pr.min(6)
    }

    /// Carries PR and RLR updates that have ended by `now` into effect.
    pub fn settle(&mut self, now: Time) {
        if let Some(t) = self.pr_update.filter(|&t| t <= now) {
            // The counter counts on at the new rate from `t`, its remaining counts kept.
            if let Some((at, left)) = self.count {
                let gone = t.saturating_sub(at) / lsi_period();
                // The counter's value then (a count in progress not yet taken off).
                let counts = left
                    .saturating_sub(gone)
                    .div_ceil(Self::divider(self.pr_active));
                self.count = Some((t, counts * Self::divider(self.pr)));
            }
            self.pr_active = self.pr;
            self.pr_update = None;
        }
        if self.rlr_update.is_some_and(|t| t <= now) {
            self.rlr_active = self.rlr;
            self.rlr_update = None;
        }
    }

    fn reload_now(&mut self, now: Time) {
        self.settle(now);
        self.count = Some((
            now,
            u64::from(self.rlr_active) * Self::divider(self.pr_active),
        ));
    }

    /// Whether the watchdog runs.
    pub fn running(&self) -> bool {
        self.count.is_some()
    }

    /// When the counter reaches 0 (the chip resets) if nothing reloads it, at the rate in
    /// effect (a prescaler update on its way is an event of its own).
    pub fn expiry(&self) -> Option<Time> {
        let (at, left) = self.count?;
        Some(at + left * lsi_period())
    }

    /// The next time something happens by itself: an update ending or the expiry.
    pub fn next_event(&self) -> Option<Time> {
        [self.pr_update, self.rlr_update, self.expiry()]
            .into_iter()
            .flatten()
            .min()
    }

    /// Register read at `now`.
    pub fn read(&mut self, off: u32, now: Time) -> Result<u32, Unmodelled> {
        self.settle(now);
        Ok(match off {
            KR => 0,
            PR => self.pr,
            RLR => self.rlr,
            SR => u32::from(self.pr_update.is_some()) | (u32::from(self.rlr_update.is_some()) << 1),
            _ => return Err(Unmodelled),
        })
    }

    /// Register write at `now`.
    pub fn write(&mut self, off: u32, v: u32, now: Time) -> Result<(), Unmodelled> {
        self.settle(now);
        match off {
            KR => match v & 0xFFFF {
                0xCCCC => {
                    self.unlocked = false;
                    if self.count.is_none() {
                        // Starts from the reset value 0xFFF (§15.3.1) ... with the RLR in effect.
                        self.reload_now(now);
                    }
                }
                0xAAAA => {
                    self.unlocked = false;
                    self.feeds += 1;
                    if self.count.is_some() {
                        self.reload_now(now);
                    }
                }
                0x5555 => self.unlocked = true,
                _ => self.unlocked = false,
            },
            PR if self.unlocked => {
                self.pr = v & 7;
                self.pr_update = Some(now + 5 * lsi_period());
            }
            RLR if self.unlocked => {
                self.rlr = v & 0xFFF;
                self.rlr_update = Some(now + 5 * lsi_period());
            }
            PR | RLR | SR => {}
            _ => return Err(Unmodelled),
        }
        Ok(())
    }
}
