//! The controller design for the accepted or loaded model, run from the board's main loop
//! (blocking, like the search: tens of milliseconds on the ATmega2560, the pump at the base
//! duty meanwhile), and the start of run mode with it. The design is on the model's dynamics,
//! from the map's flow to the measured flow (run mode goes through the map's inverse).

use ridge_core::control::{check_model, design_slower_on_failure, Design};
use ridge_core::{ArxModel, InputMap};

use crate::event::{ControlRefusal, Event, FaultReason};

use super::run::RunMode;
use super::{Phase, SelfIdentification, Settings};

/// The setpoint's reference model pole at the firmware's rate,
/// `e^{−TS_S / ridge_core::control::REFERENCE_S}` = `e^{−0.125}` (a constant: computing it
/// here cost the ATmega2560 54 bytes of flash; `firmware/tests/selfid.rs` checks it).
pub const REFERENCE_POLE: f32 = 0.882_496_9;

/// Each retry of a refused design is this much slower (`τ` and the observer pole).
pub const SLOWDOWN: f32 = 1.5;

impl<S: Settings> SelfIdentification<S> {
    /// `true` while the controller design is due: the board should call
    /// [`design`](Self::design) from its main loop.
    pub fn needs_design(&self) -> bool {
        matches!(self.phase, Phase::Design { .. })
    }

    /// Checks the model, designs the controller (slower on each failed check, up to
    /// `ControlConfig::tries` designs) and starts run mode with it: [`Event::Control`]. A model
    /// or a design that fails latches [`FaultReason::Control`] (duty 0 at once; the event is
    /// [`Event::Fault`]). Calls `pet` between the steps. `None` when no design was due.
    #[inline(never)]
    pub fn design(&mut self, mut pet: impl FnMut()) -> Option<Event> {
        let Phase::Design { model, map } = self.phase else {
            return None;
        };
        let c = &self.settings.config().control;
        pet();
        if let Err(fault) = check_model(&model, &c.model) {
            return Some(self.fault_detected(FaultReason::Control(ControlRefusal::Model(fault))));
        }
        let spec = c.spec();
        let tries = c.tries;
        let (result, tries) = design_slower_on_failure(&model, &spec, tries, SLOWDOWN, &mut pet);
        pet();
        match result {
            Ok(mut d) => {
                // Without a speed given, the setpoint response is the reference model's
                // (docs/control.md). The constant pole is not refused.
                if c.tau.is_none() {
                    d.set_reference(REFERENCE_POLE).ok();
                }
                let preview = self.start_run(model, &map, &d);
                Some(Event::Control {
                    tau: d.tau,
                    alpha: d.alpha,
                    beta: d.beta,
                    gamma: d.gamma,
                    kept: d.kept,
                    margin: d.modulus_margin,
                    tries,
                    preview,
                })
            }
            Err(error) => Some(
                self.fault_detected(FaultReason::Control(ControlRefusal::Design {
                    error,
                    tries,
                })),
            ),
        }
    }

    /// Starts run mode with the design `d` for `model` on `map`; returns its setpoint preview.
    /// Never inlined: the run mode's state (the map's table, the controller, the monitor) is
    /// built in this frame, which is gone before the design's frame is (ATmega2560 stack; in
    /// the design's frame it took 0.4 KB more of the worst-case stack).
    #[inline(never)]
    fn start_run(&mut self, model: ArxModel<f32>, map: &InputMap, d: &Design<f32>) -> u8 {
        let run = RunMode::new(
            self.settings.config(),
            model,
            map.table(),
            d,
            self.program,
            self.duty,
            self.last_counts,
        );
        let preview = run.preview();
        // The no-flow check expects the model's steady state at each duty from the first run
        // tick's PWM write on (`after_write`).
        self.phase = Phase::Run(run);
        #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
        self.reid
            .start(self.settings.config(), model, d, self.program);
        preview
    }
}

#[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
impl<S: Settings> SelfIdentification<S> {
    /// Run mode's re-identification accepted an estimate for a swap: its controller designed
    /// here, as [`design`](Self::design) designs the power-up one (the model check, the design
    /// slower on each failed check, the reference model; blocking, after the PWM write) but at
    /// the power-up design's regulation speed ([`RunMode::speed`]), then
    /// swapped in by run mode at the next breath boundary as the controller sees it. A refused
    /// model or design keeps the running model and controller and says why
    /// (`REID … verdict=design why=…`) into `event` if empty. Nothing when no estimate waits.
    ///
    /// The same steps as [`design`](Self::design), written again: sharing one function cost the
    /// ATmega2560 image 0.9 KB (its inlining changed). Never inlined: its design's temporaries
    /// stay out of the board's tick's frame (ATmega2560 stack, docs/boards.md).
    #[inline(never)]
    pub(super) fn redesign(&mut self, event: &mut Option<Event>) {
        let c = &self.settings.config().control;
        let Phase::Run(run) = &self.phase else {
            return;
        };
        let re = &mut self.reid;
        let Some(model) = re.take_candidate() else {
            return;
        };
        if let Err(m) = check_model(&model, &c.model) {
            run.swap_refused(re, &model, ControlRefusal::Model(m), event);
            return;
        }
        // At the power-up design's speed, not the one the default takes from the new model.
        let spec = ridge_core::control::Spec {
            tau: Some(re.speed()),
            ..c.spec()
        };
        match design_slower_on_failure(&model, &spec, c.tries, SLOWDOWN, || {}) {
            (Ok(mut d), _) => {
                if c.tau.is_none() {
                    d.set_reference(REFERENCE_POLE).ok();
                }
                re.set_swap(model, d, event);
            }
            (Err(error), tries) => {
                run.swap_refused(re, &model, ControlRefusal::Design { error, tries }, event)
            }
        }
    }
}
