//! Run-mode tracking figures and the tracking alarm.
//!
//! Every tick takes the program's setpoint for the interval that just ended (not the one the
//! controller was given ahead of time, see `selfid::run`), the
//! reading at its end and the duty applied. Once per window ([`TrackingConfig::window`] ticks,
//! 1 s) it reports [`Event::Track`]: mean setpoint, mean flow, RMS and largest |error|, mean
//! duty, and the ticks since run mode started. The **alarm** ([`Event::Alarm`]) is raised when the error `setpoint − flow` stays
//! outside the band `band_abs + band_rel · |setpoint|` for [`TrackingConfig::alarm_ticks`]
//! consecutive ticks (an occlusion, a leak, a pump that cannot deliver the setpoint), and
//! cleared when it has been back inside for as long. Ticks without a reading are not scored.

use crate::event::Event;

/// Settings of the tracking figures and the alarm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingConfig {
    /// Ticks per [`Event::Track`] (100 = 1 s); 0 counts as 1.
    pub window: u8,
    /// Absolute part of the alarm band, slm (default 3).
    pub band_abs: f32,
    /// Relative part of the alarm band, fraction of |setpoint| (default 0.15).
    pub band_rel: f32,
    /// Consecutive ticks out of (back in) the band that raise (clear) the alarm (default 50 =
    /// 0.5 s: longer than the transient of a setpoint step or a breath's rise).
    pub alarm_ticks: u16,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl TrackingConfig {
    /// The defaults: 1 s windows, band 3 slm + 15 %, 0.5 s to raise or clear the alarm.
    pub const DEFAULT: TrackingConfig = TrackingConfig {
        window: 100,
        band_abs: 3.0,
        band_rel: 0.15,
        alarm_ticks: 50,
    };
}

/// The tracking figures of run mode (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tracking {
    cfg: TrackingConfig,
    ticks: u8,
    n: u16,
    sum_r: f32,
    sum_y: f32,
    sum_e2: f32,
    max_e: f32,
    sum_duty: u32,
    /// Consecutive ticks out of the band (raising) or in it (clearing).
    run: u16,
    alarm: bool,
    /// A window closed in a tick that reported an alarm change: report it next tick.
    pending: bool,
    /// Ticks stepped since the start.
    count: u32,
}

impl Tracking {
    /// Figures at zero. The first window closes after `offset` ticks (so that its line does
    /// not fall on the same tick as another once-a-second line), then every window.
    pub fn new(cfg: TrackingConfig, offset: u8) -> Self {
        Tracking {
            cfg,
            ticks: cfg
                .window
                .max(1)
                .saturating_sub(offset.min(cfg.window.max(1) - 1)),
            n: 0,
            sum_r: 0.0,
            sum_y: 0.0,
            sum_e2: 0.0,
            max_e: 0.0,
            sum_duty: 0,
            run: 0,
            alarm: false,
            pending: false,
            count: 0,
        }
    }

    /// Whether the alarm is raised.
    pub fn alarm(&self) -> bool {
        self.alarm
    }

    /// One tick: the setpoint `r` (slm) of the interval that ended, its reading `y` (slm,
    /// `None` after a sensor error) and the duty applied (1/10 000). Puts an alarm change, or
    /// the window's figures when it closes, into `event` if that is empty; if another event
    /// already takes this tick's line, both wait for the next tick: none is lost. (Written in
    /// place, not returned: a returned event is a 74-byte copy, ~550 cycles on the ATmega2560
    /// inside the control tick.)
    pub fn step(&mut self, r: f32, y: Option<f32>, duty: u16, event: &mut Option<Event>) {
        let busy = event.is_some();
        if let Some(y) = y {
            let e = r - y;
            let ae = if e < 0.0 { -e } else { e };
            self.n = self.n.saturating_add(1);
            self.sum_r += r;
            self.sum_y += y;
            self.sum_e2 += e * e;
            if ae > self.max_e || ae.is_nan() {
                self.max_e = ae;
            }
            self.sum_duty = self.sum_duty.saturating_add(u32::from(duty));
            let ar = if r < 0.0 { -r } else { r };
            // Out of band, or NaN.
            let band = self.cfg.band_abs + self.cfg.band_rel * ar;
            let out = ae > band || ae.is_nan();
            if out != self.alarm {
                self.run = self.run.saturating_add(1);
                if self.run >= self.cfg.alarm_ticks.max(1) && !busy {
                    self.alarm = out;
                    self.run = 0;
                    *event = Some(Event::Alarm {
                        on: out,
                        error: e,
                        ticks: self.cfg.alarm_ticks.max(1),
                    });
                }
            } else {
                self.run = 0;
            }
        }
        self.count = self.count.saturating_add(1);
        self.ticks = self.ticks.saturating_sub(1);
        if self.ticks == 0 {
            self.ticks = self.cfg.window.max(1);
            self.pending = true;
        }
        if event.is_none() && self.pending {
            self.pending = false;
            self.close_window(event);
        }
    }

    /// The window's figures into `event` (nothing without a scored sample), and a fresh window.
    fn close_window(&mut self, event: &mut Option<Event>) {
        if self.n > 0 {
            *event = Some(Event::Track {
                sum_setpoint: self.sum_r,
                sum_flow: self.sum_y,
                sum_sq: self.sum_e2,
                max: self.max_e,
                sum_duty: self.sum_duty,
                samples: self.n,
                tick: self.count,
            });
        }
        self.n = 0;
        self.sum_r = 0.0;
        self.sum_y = 0.0;
        self.sum_e2 = 0.0;
        self.max_e = 0.0;
        self.sum_duty = 0;
    }
}
