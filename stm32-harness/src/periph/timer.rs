//! General-purpose timers TIM2 to TIM5 (RM0383 §13), as the image uses two of them: TIM3 in
//! PWM mode 1 on channel 1 (the pump, 20 kHz) and TIM5 as a free-running 32-bit counter at
//! 10 kHz (the loop tick, polled).
//!
//! Modelled:
//! - the time base (§13.3.1, §13.3.2): with `TIMx_CR1.CEN` set the counter counts up at
//!   f_CK_CNT = f_CK_PSC / (PSC + 1) and wraps from ARR to 0 (upcounting, §13.3.2
//!   "Upcounting mode"); `CNT` is computed from emulated time, so it counts on while the CPU is
//!   stalled. TIM2 and TIM5 count 32 bits, TIM3 and TIM4 16 bits (§13.4.10).
//! - `PSC` is preloaded: a new value takes effect at the next update event (§13.3.1); `ARR`
//!   too when `CR1.ARPE` is set, else at once. An update event (overflow, or `EGR.UG`,
//!   §13.4.6) reloads them; UG also clears the counter and the prescaler counter, and sets
//!   `SR.UIF` unless `CR1.URS` is set (§13.4.1) — as overflow sets UIF.
//! - PWM (§13.3.9, "PWM mode"): channel 1's output is high while CNT < CCR1 in PWM mode 1
//!   (`CCMR1.OC1M` = 110) and enabled (`CCER.CC1E`): its duty is CCR1 / (ARR + 1), 0 when
//!   CCR1 = 0, 1 when CCR1 > ARR. `CCR1` preload (`OC1PE`) is not modelled: a write takes
//!   effect at once (at most one PWM period early, 50 µs at 20 kHz).
//! - the other registers (CR2, SMCR, DIER, CCMR2, CCR2–4, DCR, DMAR, OR) are stored.
//!   Simplification: no interrupts, DMA, input capture, slave modes or other counting modes
//!   (the image uses none); `DIR`/`CMS` other than up-counting are reported as unmodelled.

use super::{cycles_to_ps, ps_to_cycles, Time, Unmodelled};

/// Register offsets (§13.4.21, register map).
pub const CR1: u32 = 0x00;
/// Event generation.
pub const EGR: u32 = 0x14;
/// Status.
pub const SR: u32 = 0x10;
/// Capture/compare mode 1.
pub const CCMR1: u32 = 0x18;
/// Capture/compare enable.
pub const CCER: u32 = 0x20;
/// Counter.
pub const CNT: u32 = 0x24;
/// Prescaler.
pub const PSC: u32 = 0x28;
/// Auto-reload.
pub const ARR: u32 = 0x2C;
/// Capture/compare 1.
pub const CCR1: u32 = 0x34;

const CR1_CEN: u32 = 1 << 0;
const CR1_URS: u32 = 1 << 2;
const CR1_DIR_CMS: u32 = (1 << 4) | (3 << 5);
const CR1_ARPE: u32 = 1 << 7;
const SR_UIF: u32 = 1;

/// One general-purpose timer.
#[derive(Clone, Debug)]
pub struct Timer {
    /// Counter width: 32 (TIM2, TIM5) or 16 (TIM3, TIM4) bits.
    wide: bool,
    regs: [u32; 0x58 / 4],
    /// Prescaler and auto-reload in effect (the preload registers' shadows).
    psc_active: u32,
    arr_active: u32,
    /// Counter value at `base` and the time from which it counts on (only while CEN).
    cnt_base: u32,
    base: Time,
    /// Timer kernel clock, Hz.
    clock_hz: u32,
}

impl Timer {
    /// A timer at reset with a 32-bit (`wide`) or 16-bit counter.
    pub fn new(wide: bool) -> Self {
        Timer {
            wide,
            regs: [0; 0x58 / 4],
            psc_active: 0,
            arr_active: if wide { u32::MAX } else { 0xFFFF },
            cnt_base: 0,
            base: 0,
            clock_hz: 16_000_000,
        }
    }

    /// Reset values (§13.4): everything 0, ARR all ones.
    pub fn reset(&mut self) {
        *self = Timer::new(self.wide);
    }

    fn mask(&self) -> u32 {
        if self.wide {
            u32::MAX
        } else {
            0xFFFF
        }
    }

    fn running(&self) -> bool {
        self.regs[0] & CR1_CEN != 0
    }

    /// Counter ticks in `dt` ps at the active prescaler.
    fn ticks(&self, dt: Time) -> u64 {
        ps_to_cycles(dt, self.clock_hz) / (u64::from(self.psc_active) + 1)
    }

    /// The counter at `now`.
    pub fn count(&self, now: Time) -> u32 {
        if !self.running() {
            return self.cnt_base;
        }
        let period = u64::from(self.arr_active) + 1;
        let ticks = self.ticks(now.saturating_sub(self.base));
        ((u64::from(self.cnt_base) + ticks) % period.max(1)) as u32
    }

    /// Settles the counter at `now` (before a register change that affects counting), taking
    /// pending overflows into account (a preloaded PSC/ARR takes effect at the first one).
    fn settle(&mut self, now: Time) {
        if self.running() {
            let period = u64::from(self.arr_active) + 1;
            let total = u64::from(self.cnt_base) + self.ticks(now.saturating_sub(self.base));
            if total >= period {
                self.regs[4] |= SR_UIF;
                self.psc_active = self.regs[(PSC / 4) as usize];
                self.arr_active = self.regs[(ARR / 4) as usize];
            }
            self.cnt_base = (total % period.max(1)) as u32;
        }
        self.base = now;
    }

    /// Sets the kernel clock (from the RCC) at `now`.
    pub fn set_clock(&mut self, hz: u32, now: Time) {
        if hz != self.clock_hz {
            self.settle(now);
            self.clock_hz = hz;
        }
    }

    /// When the counter next changes value by itself (the next count), if it counts.
    pub fn next_change(&self, now: Time) -> Option<Time> {
        if !self.running() {
            return None;
        }
        let per_tick = u64::from(self.psc_active) + 1;
        let cycles = ps_to_cycles(now.saturating_sub(self.base), self.clock_hz);
        let next = (cycles / per_tick + 1) * per_tick;
        Some(self.base + cycles_to_ps(next, self.clock_hz) + 1)
    }

    /// Duty of channel 1's output, 0..1 (see the module docs), or `None` when the channel is
    /// not driving (not in PWM mode 1 or 2, or not enabled, or the timer stopped).
    pub fn duty_ch1(&self) -> Option<f64> {
        let ccmr1 = self.regs[(CCMR1 / 4) as usize];
        let oc1m = (ccmr1 >> 4) & 7;
        let cc1e = self.regs[(CCER / 4) as usize] & 1 != 0;
        if !cc1e || ccmr1 & 3 != 0 || !self.running() {
            return None;
        }
        let ccr = u64::from(self.regs[(CCR1 / 4) as usize]);
        let period = u64::from(self.arr_active) + 1;
        let high = ccr.min(period) as f64 / period as f64;
        match oc1m {
            6 => Some(high),
            7 => Some(1.0 - high),
            // Forced levels (§13.4.7): 100 inactive, 101 active.
            4 => Some(0.0),
            5 => Some(1.0),
            _ => None,
        }
    }

    /// `CCR1` and the period `ARR + 1` in effect.
    pub fn ch1_counts(&self) -> (u32, u32) {
        (
            self.regs[(CCR1 / 4) as usize],
            self.arr_active.wrapping_add(1),
        )
    }

    /// Register read at `now`.
    pub fn read(&mut self, off: u32, now: Time) -> Result<u32, Unmodelled> {
        if off % 4 != 0 || off >= 0x58 {
            return Err(Unmodelled);
        }
        Ok(match off {
            CNT => self.count(now),
            EGR => 0,
            SR => {
                self.settle(now);
                self.regs[4]
            }
            _ => self.regs[(off / 4) as usize],
        })
    }

    /// Register write at `now`.
    pub fn write(&mut self, off: u32, v: u32, now: Time) -> Result<(), Unmodelled> {
        if off % 4 != 0 || off >= 0x58 {
            return Err(Unmodelled);
        }
        self.settle(now);
        match off {
            CR1 => {
                if v & CR1_DIR_CMS != 0 {
                    return Err(Unmodelled);
                }
                self.regs[0] = v & 0x3FF;
            }
            // rc_w0 flags (§13.4.5).
            SR => self.regs[4] &= v,
            EGR => {
                if v & 1 != 0 {
                    // UG: reinitialise the counter and the prescaler counter, update the
                    // shadow registers (§13.4.6).
                    self.cnt_base = 0;
                    self.psc_active = self.regs[(PSC / 4) as usize];
                    self.arr_active = self.regs[(ARR / 4) as usize];
                    if self.regs[0] & CR1_URS == 0 {
                        self.regs[4] |= SR_UIF;
                    }
                }
            }
            CNT => self.cnt_base = v & self.mask(),
            PSC => self.regs[(PSC / 4) as usize] = v & 0xFFFF,
            ARR => {
                let arr = v & self.mask();
                self.regs[(ARR / 4) as usize] = arr;
                if self.regs[0] & CR1_ARPE == 0 {
                    self.arr_active = arr;
                }
            }
            _ => self.regs[(off / 4) as usize] = v,
        }
        Ok(())
    }
}
