//! The operator's commands on the state machine (see [`crate::command`]): stop, start, and the
//! setpoint program run mode tracks.

use ridge_core::control::Controller;

use crate::command::{Milli, ProfileArgs, VentArgs};
use crate::setpoint::{Breath, BreathWave, Program, DEMO_BREATH};
use crate::units::{FLOW_SCALE, SLM_PER_COUNT};

use super::{Guard, Phase, SelfIdentification, Settings};

/// `x` in thousandths, truncated (for the [`DEMO_BREATH`] defaults, at compile time).
const fn milli(x: f32) -> Milli {
    (x * 1000.0) as Milli
}

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

    /// Run mode tracks the breath of a `PROFILE` command: the values given, [`DEMO_BREATH`]'s
    /// for the keys left out. Checked exactly, in thousandths (`Err("rate" | "ie" | "rise" |
    /// "flow")`, nothing changes): 0 < rate ≤ 60 /min, 0 < ie ≤ 10, 0 ≤ rise ≤ half the
    /// inspiration `30 / (rate · (1 + ie))` s ([`Breath::check`]'s bounds), both flows in 0 ..=
    /// the flow limit. Integer tests instead of [`Breath::check`] on the converted values:
    /// 0.3 KB less of the ATmega2560's flash, and no rounding at the limits.
    pub fn set_profile(&mut self, args: &ProfileArgs) -> Result<(), &'static str> {
        let rate = args.rate.unwrap_or(const { milli(DEMO_BREATH.rate) });
        let ie = args.ie.unwrap_or(const { milli(DEMO_BREATH.ie) });
        let peak = args.peak.unwrap_or(const { milli(DEMO_BREATH.peak) });
        let bias = args.bias.unwrap_or(const { milli(DEMO_BREATH.bias) });
        let rise = args.rise.unwrap_or(const { milli(DEMO_BREATH.rise) });
        if rate <= 0 || rate > 60_000 {
            return Err("rate");
        }
        if ie <= 0 || ie > 10_000 {
            return Err("ie");
        }
        // rise/10³ ≤ 30 / (rate/10³ · (10³ + ie)/10³) ⇔ rise · rate · (10³ + ie) ≤ 3·10¹⁰,
        // in i64 (at most 10⁹ · 6·10⁴ · 1.1·10⁴ < 2⁶³).
        let span = i64::from(rise) * i64::from(rate) * i64::from(1_000 + ie);
        if rise < 0 || span > 30_000_000_000 {
            return Err("rise");
        }
        // slm ≤ limit / FLOW_SCALE ⇔ milli · FLOW_SCALE ≤ limit · 10³ (i64: no overflow).
        let max = i64::from(self.settings.config().flow_limit) * 1_000;
        let scale = i64::from(FLOW_SCALE);
        if peak < 0 || bias < 0 || i64::from(peak) * scale > max || i64::from(bias) * scale > max {
            return Err("flow");
        }
        let value = |m: Milli| m as f32 / 1000.0;
        let breath = Breath {
            shape: args.shape,
            rate: value(rate),
            ie: value(ie),
            peak: value(peak),
            bias: value(bias),
            rise: value(rise),
        };
        self.use_program(Program::Breath(BreathWave::new(&breath)));
        Ok(())
    }

    /// Run mode ventilates: volume-controlled breaths of a `VENT` command, checked by
    /// [`ventilation::settings`](crate::ventilation::settings) (`Err(<setting>)`, nothing
    /// changes), from now (or from the start of run mode): a lead-in of one expiration, then
    /// breath 1 ([`crate::setpoint`]'s module docs).
    pub fn set_vent(&mut self, args: &VentArgs) -> Result<(), &'static str> {
        let breath = crate::ventilation::settings(args, self.settings.config().flow_limit)?;
        self.use_program(Program::Volume(breath));
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
        // A volume program pauses the no-flow check at its first tick; any other ends a pause.
        if !matches!(program, Program::Volume(_)) {
            self.guard.resume_expectation();
        }
        if let Phase::Run(run) = &mut self.phase {
            run.set_program(program);
            #[cfg(any(not(target_arch = "avr"), feature = "atmega2560-reid"))]
            self.reid.restart(program);
        }
    }
}
