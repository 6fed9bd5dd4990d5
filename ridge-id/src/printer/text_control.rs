//! The text printer's section of `--control`: the controller design, or why it was refused
//! ([`ControlReport::to_text`]).

use std::fmt::Write as _;

use crate::control::{pole_list, ControlReport, EXIT_REFUSED, SLOWDOWN, TRIES};
use crate::numfmt::{list, num};

impl ControlReport {
    /// The readable section of the report (appended to the identification's).
    pub fn to_text(&self) -> String {
        let mut o = String::new();
        let ts = self.options.ts;
        let _ = writeln!(
            o,
            "  Controller (--control): pole placement with integral action, ridge-core's design \
             as the firmware runs it, Ts = {} s",
            num(ts)
        );
        let gain_range = match (self.options.gain_min, self.options.gain_max) {
            (None, None) => "> 0".to_string(),
            (None, Some(b)) => format!("in (0, {}]", num(b)),
            (Some(a), None) => format!(">= {}", num(a)),
            (Some(a), Some(b)) => format!("in [{}, {}]", num(a), num(b)),
        };
        let largest = self.model_poles.first().map_or(f64::NAN, |p| p.norm());
        let _ = writeln!(
            o,
            "  model check   poles within {} (largest |z| {}), static gain {} {gain_range}",
            self.limits.stable_radius,
            num(largest),
            num(self.gain),
        );
        let _ = writeln!(o, "  model poles   {}", pole_list(&self.model_poles));
        match &self.outcome {
            Err(r) => {
                let _ = writeln!(o, "  REFUSED       {}", r.reason);
                let _ = writeln!(
                    o,
                    "  (check: {}; designs made: {}; exit status {EXIT_REFUSED})",
                    r.check.name(),
                    r.tries
                );
            }
            Ok(c) => {
                let d = &c.design;
                let _ = writeln!(o, "  method        pole-placement");
                // ridge-core clamps the derived τ to 2 Ts..2 s, the ceiling last: at Ts > 1 s
                // the result is 2 s, below its own floor.
                let base = d.tau / d.spec.slowdown;
                let slow_pole = self
                    .model_poles
                    .iter()
                    .any(|p| p.norm() >= d.spec.keep_radius);
                let how = if !c.tau_derived {
                    "--speed"
                } else if !slow_pole {
                    "derived: ridge-core's 0.1 s for a model without a slow pole"
                } else if (base - 2.0).abs() < 1e-9 && base < 2.0 * ts {
                    "derived: ridge-core's 2 s ceiling, below its 2 Ts floor (set --speed)"
                } else if (base - 2.0).abs() < 1e-9 {
                    "derived: ridge-core's 2 s ceiling"
                } else {
                    "derived: a quarter of the slow pole's time constant"
                };
                let slowed = if c.tries > 1 {
                    format!(" = {} s x {} (slowed)", num(base), num(d.spec.slowdown))
                } else {
                    String::new()
                };
                let _ = writeln!(o, "  tau           {} s{slowed}, {how}", num(d.tau));
                let _ = writeln!(
                    o,
                    "  alpha         {} (regulation pole, exp(-Ts/tau))",
                    num(d.alpha)
                );
                let _ = writeln!(
                    o,
                    "  beta          {} (observer pole, tau_o {} s)",
                    num(d.beta),
                    num(d.spec.observer * d.spec.slowdown)
                );
                match c.reference_s {
                    Some(tau_ref) => {
                        let _ = writeln!(
                            o,
                            "  reference     {} s (setpoint response pole {}: the setpoint goes \
                             through a first-order reference model, alpha cancelled)",
                            num(tau_ref),
                            num(d.gamma)
                        );
                    }
                    None => {
                        let _ = writeln!(o, "  reference     none (setpoint response pole alpha)");
                    }
                }
                let _ = writeln!(
                    o,
                    "  kept          {} model pole(s) (those within {} of 0; a slow real pole is moved to alpha)",
                    d.kept, d.spec.keep_radius
                );
                let _ = writeln!(
                    o,
                    "  margin        {} (modulus margin 1 / max |A R / P|, at least {})",
                    num(d.modulus_margin),
                    d.spec.min_margin
                );
                let _ = writeln!(
                    o,
                    "  tries         {} (at most {TRIES}, each {SLOWDOWN} times slower)",
                    c.tries
                );
                let _ = writeln!(
                    o,
                    "  mean delay    {} samples ({} s) of the setpoint response",
                    num(c.mean_delay),
                    num(c.mean_delay * ts)
                );
                let _ = writeln!(o, "  R = {}", list(&c.r));
                let _ = writeln!(o, "  S = {}", list(&c.s));
                let _ = writeln!(o, "  T = {}", list(&c.t));
                let _ = writeln!(
                    o,
                    "  R(q^-1) u(t+1) = T(q^-1) r(t+1) - S(q^-1) y(t), ascending powers of q^-1{}",
                    if c.reference_s.is_some() {
                        " (the reference model multiplied in: R and S carry its (1 - gamma q^-1))"
                    } else {
                        ""
                    }
                );
                let _ = writeln!(
                    o,
                    "  closed-loop poles (roots of P = A R + q^-(d+1) B S, degree {}):",
                    c.closed_loop.len().saturating_sub(1)
                );
                if c.poles.is_empty() {
                    let _ = writeln!(o, "    (could not be computed)");
                }
                let at_origin = c.poles.iter().filter(|p| p.norm() == 0.0).count();
                for p in c.poles.iter().filter(|p| p.norm() != 0.0) {
                    let _ = writeln!(
                        o,
                        "    {:>10.6} {} {:>9.6}i   |z| {:.6}",
                        p.re,
                        if p.im < 0.0 { "-" } else { "+" },
                        p.im.abs(),
                        p.norm()
                    );
                }
                if at_origin > 0 {
                    let _ = writeln!(
                        o,
                        "    {:>10.6} + {:>9.6}i   |z| {:.6}   ({at_origin} at the origin)",
                        0.0, 0.0, 0.0
                    );
                }
            }
        }
        o
    }
}
