//! Instruction counting on QEMU, which has no DWT cycle counter.
//!
//! With `-icount shift=S` QEMU advances its virtual clock by `2^S` ns per guest
//! instruction; the MPS2 SysTick, clocked from the 25 MHz system clock
//! (`CLKSOURCE = 1`), ticks every 40 ns of that clock. So
//! `instructions = ticks · 40 / 2^S`, i.e. `ticks · 40 / 64` for `shift=6`.
//! [`calibrate`] checks this against a loop of known length.
//!
//! SysTick is 24-bit: the binary's `SysTick` exception handler must call
//! [`on_wrap`] so that [`now`] keeps counting past 2^24 ticks (0.67 s virtual).

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;

/// The `-icount shift` the runner is configured with (`.cargo/config.toml`).
pub const ICOUNT_SHIFT: u32 = 6;
/// Nanoseconds per SysTick tick at the MPS2 25 MHz system clock.
pub const NS_PER_TICK: u64 = 40;

const RELOAD: u32 = 0x00FF_FFFF;
static WRAPS: AtomicU32 = AtomicU32::new(0);

/// Starts SysTick free-running from the core clock with its wrap interrupt enabled.
pub fn start(syst: &mut SYST) {
    syst.disable_counter();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Call from the `SysTick` exception handler.
pub fn on_wrap() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// Ticks since [`start`] (64-bit, wrap-extended).
#[inline(never)]
pub fn now() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::Relaxed);
        let v = SYST::get_current();
        if WRAPS.load(Ordering::Relaxed) == w {
            return u64::from(w) * (u64::from(RELOAD) + 1) + u64::from(RELOAD - v);
        }
    }
}

/// Ticks to guest instructions (valid only with `-icount shift=ICOUNT_SHIFT`).
pub fn instructions(ticks: u64) -> u64 {
    (ticks * NS_PER_TICK + (1 << (ICOUNT_SHIFT - 1))) >> ICOUNT_SHIFT
}

/// Exactly `2 n` instructions (`subs` + `bne` per iteration), `n ≥ 1`.
#[inline(never)]
pub fn spin(n: u32) {
    // SAFETY: register-only loop, no memory access.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {0}, {0}, #1",
            "bne 2b",
            inout(reg) n.max(1) => _,
            options(nomem, nostack),
        );
    }
}

/// Ticks of `f()`, minus the cost of an empty measurement.
pub fn measure<R>(f: impl FnOnce() -> R) -> (u64, R) {
    let t0 = now();
    let r = f();
    let t1 = now();
    let empty = {
        let a = now();
        let b = now();
        b - a
    };
    ((t1 - t0).saturating_sub(empty), r)
}

/// Measured instructions of `spin(n2)` minus `spin(n1)`; with icount this equals
/// `2 (n2 − n1)` up to one tick of rounding.
pub fn calibrate(n1: u32, n2: u32) -> (u64, u64) {
    let (a, _) = measure(|| spin(n1));
    let (b, _) = measure(|| spin(n2));
    (a, b)
}
