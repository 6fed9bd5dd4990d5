//! The operator's commands on the state machine (see [`crate::command`]): stop, start, and the
//! setpoint program run mode tracks.

use ridge_core::control::Controller;

use crate::setpoint::{Breath, BreathWave, Program};
use crate::units::SLM_PER_COUNT;

use super::{Guard, Phase, SelfIdentification, Settings};

impl<S: Settings> SelfIdentification<S> {
    /// Stops the pump: the duty is 0 from now on (the caller stops the PWM in the same tick)
    /// until [`start`](Self::start). A record or search in progress is dropped; the model in
    /// use is kept. A latched fault stays latched (and reported as such).
    pub fn stop(&mut self) {
        if matches!(self.phase, Phase::Fault) {
            return;
        }
        self.phase = Phase::Stopped;
        self.duty = 0;
        self.generation = self.generation.wrapping_add(1);
    }

    /// Leaves the stopped or the fault state and starts as after a reset: wait for a good
    /// reading, settle, then run the model in use (its controller is designed again) or
    /// identify one. `false` (nothing changes) in any other state.
    pub fn start(&mut self) -> bool {
        if !matches!(self.phase, Phase::Stopped | Phase::Fault) {
            return false;
        }
        self.phase = Phase::Wait;
        self.duty = 0;
        self.guard = Guard::new(self.settings.config());
        self.fault = None;
        self.fault_announced = false;
        self.attempt = 0;
        self.identify = false;
        self.generation = self.generation.wrapping_add(1);
        true
    }

    /// Run mode tracks the constant flow `slm` (now, or from its start). `Err("flow")` (nothing
    /// changes) unless 0 ≤ `slm` ≤ the configured flow limit.
    pub fn set_flow(&mut self, slm: f32) -> Result<(), &'static str> {
        self.check_flow(slm)?;
        self.use_program(Program::Constant(slm));
        Ok(())
    }

    /// Run mode tracks `breath` (now, or from its start). `Err(<setting>)` (nothing changes)
    /// when [`Breath::check`] refuses it or a flow is outside 0 ..= the flow limit (`"flow"`).
    pub fn set_breath(&mut self, breath: &Breath) -> Result<(), &'static str> {
        breath.check()?;
        self.check_flow(breath.peak)?;
        self.check_flow(breath.bias)?;
        self.use_program(Program::Breath(BreathWave::new(breath)));
        Ok(())
    }

    /// What run mode tracks (or will track).
    pub fn program(&self) -> Program {
        self.program
    }

    /// The flow controller in run mode.
    pub fn controller(&self) -> Option<&Controller<f32>> {
        match &self.phase {
            Phase::Run(run) => Some(run.controller()),
            _ => None,
        }
    }

    fn check_flow(&self, slm: f32) -> Result<(), &'static str> {
        let max = f32::from(self.settings.config().flow_limit) * SLM_PER_COUNT;
        // Written so that NaN fails.
        if slm >= 0.0 && slm <= max {
            Ok(())
        } else {
            Err("flow")
        }
    }

    fn use_program(&mut self, program: Program) {
        self.program = program;
        if let Phase::Run(run) = &mut self.phase {
            run.set_program(program);
        }
    }
}
