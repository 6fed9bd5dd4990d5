//! The bench: the simulated ATmega2560 (simavr, running the firmware image) wired to the
//! simulated plant, closed loop: firmware in simavr ⇄ simulated SFM3300 on TWI ⇄ blower model
//! driven by the PWM the firmware actually programs.
//!
//! The plant is the same blower and sensor models that `pump_sim::Rig` steps once per 10 ms
//! sample, but the bench drives them itself, finer and from the MCU's registers: every 0.5 ms
//! of simulated time (the SFM3300's update period) it reads the PWM duty from the timer
//! registers ([`pwm`]), steps the blower model by 0.5 ms with it and hands the new
//! flow to the sensor. The blower is `pump_sim::Pump` with its 100 Hz parameters sub-stepped
//! 20× (time constants are exact under zero-order hold; the transport delay is kept in time,
//! 20 sub-steps per 10 ms sample). With a test lung (`pump_sim::Lung`) the blower's open-outlet
//! flow and shut-off pressure feed the lung at every sub-step, and the sensor measures the flow
//! against the lung's back pressure. The lung's exhalation valve is the firmware's output pin
//! (D22 = PA0 on the ATmega2560, high = closed), read from the port registers at every sub-step
//! like the PWM: each closing of the valve starts a breath, and the bench records each
//! breath's truth from the lung ([`BreathTruth`]: delivered volume, peak airway pressure, PEEP).
//!
//! Timing is measured from the core's cycle counter, with no help from the firmware
//! ([`crate::ticks`]: tick start and end, missed ticks, control latency).

use std::cell::{Cell, RefCell};

use std::path::PathBuf;
use std::rc::Rc;

use crate::bus::{self, BusState, SdaHold};
use crate::machine::{Halt, Machine, UartByte};
use crate::pwm::{self, Channel};
use crate::sensor::{Fault, SensorState, Sfm3300Slave};
use crate::ticks::TickMeter;
use crate::transcript::{Line, LineSplitter};
use crate::uart::{SendId, SerialLine, Transmission, UartInput, UartTiming, BAUD};
use pump_sim::{Lung, LungParams, Pump, PumpParams, Sfm3300, Sfm3300Params, Valve};

pub use crate::ticks::TickTiming;

/// Plant sub-steps per 10 ms sample (0.5 ms each: the SFM3300 update period).
pub const SUBSTEPS: usize = 20;
/// Vector number of TIMER3_COMPA (the board's 100 Hz tick), counted from 0 = RESET as avr-libc's
/// `__vector_N` symbols and simavr do (the ATmega2560 datasheet's "Reset and Interrupt Vectors"
/// table counts from 1 and lists it as vector 33, program address `0x0040`).
pub const TIMER3_COMPA: u8 = 32;

/// Bench settings.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    /// Firmware ELF.
    pub elf: PathBuf,
    /// Core clock, Hz.
    pub frequency: u32,
    /// Blower (100 Hz parameters; the bench sub-steps it).
    pub pump: PumpParams,
    /// Test lung behind the blower, `None` for an open outlet.
    pub lung: Option<LungParams>,
    /// Sensor error model.
    pub sensor: Sfm3300Params,
    /// Sensor noise seed.
    pub seed: u64,
    /// PWM channel driving the blower; `None`: the first 16-bit channel seen driving a pin.
    pub pwm: Option<Channel>,
    /// Interrupt vector of the tick; `None`: no tick timing.
    pub tick_vector: Option<u8>,
    /// EEPROM contents to program before reset (offset, bytes).
    pub eeprom: Vec<(u16, Vec<u8>)>,
    /// How USART0's frames are timed (transmit and receive; [`crate::uart`]).
    pub uart_timing: UartTiming,
    /// The exhalation valve's output pin (port, bit; high = closed), `None`: always open.
    pub valve_pin: Option<(char, u8)>,
}

impl BenchConfig {
    /// ATmega2560 at 16 MHz, default pump and sensor, seed 1, OC4A (the board's pump PWM),
    /// TIMER3_COMPA tick, simavr's own UART timing.
    pub fn new(elf: impl Into<PathBuf>) -> Self {
        Self {
            elf: elf.into(),
            frequency: 16_000_000,
            pump: PumpParams::default(),
            lung: None,
            sensor: Sfm3300Params::default(),
            seed: 1,
            pwm: Some(Channel {
                timer: 4,
                channel: 'A',
            }),
            tick_vector: Some(TIMER3_COMPA),
            eeprom: Vec::new(),
            uart_timing: UartTiming::Simavr,
            valve_pin: Some(VALVE_PIN),
        }
    }
}

/// The ATmega2560 board's exhalation valve pin: D22 = PA0 (docs/boards.md).
pub const VALVE_PIN: (char, u8) = ('A', 0);

/// One breath as the simulated lung saw it: from a closing of the exhalation valve to the
/// next (the simulator's truth, beside the firmware's `BREATH` lines).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BreathTruth {
    /// Core cycle of the plant step that saw the valve close.
    pub start: u64,
    /// Core cycle of the plant step that saw it open again (`None`: still closed).
    pub open: Option<u64>,
    /// Volume the lung gained while the valve was closed, mL (the delivered tidal volume).
    pub delivered: f64,
    /// Lung pressure when the valve closed: the end-expiratory pressure (PEEP) of the
    /// expiration before, cmH₂O.
    pub peep: f64,
    /// Largest airway pressure (blower outlet) from the closing to the next one, cmH₂O.
    pub peak_pressure: f64,
    /// Largest true flow while the valve was closed (the inspiration), slm: the span of the
    /// firmware's `BREATH` peak. The largest flow of the whole breath comes just after the
    /// valve opens (the blower still at the inspiration's duty, into the open valve), which
    /// the firmware's inspiratory peak does not cover.
    pub peak_flow: f64,
    /// Lung volume at the closing, mL (for the delivered volume).
    volume_at_close: f64,
}

/// A PWM change seen at a plant step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DutyChange {
    /// Core cycle of the plant step that saw it (≤ 0.5 ms after the write).
    pub cycle: u64,
    /// Duty fraction 0..1 on the pin.
    pub fraction: f64,
    /// Compare register (0 when disconnected).
    pub ocr: u16,
    /// Timer TOP.
    pub top: u16,
    /// Compare output connected to the pin.
    pub connected: bool,
}

/// One 10 ms plant sample (every 20th sub-step), for plots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantSample {
    /// Core cycle.
    pub cycle: u64,
    /// Duty on the pin, 0..1.
    pub duty: f64,
    /// True flow, slm.
    pub flow: f64,
}

/// Scheduled change during a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Set the sensor fault.
    Sensor(Fault),
    /// Block or free the rotor.
    Stall(bool),
    /// The sensor holds SDA low from the firmware's next STOP request on (see [`bus`]).
    HoldSda(SdaHold),
    /// The test lung's parameters change now, its volume kept (a sudden change of
    /// compliance, resistance, PEEP or leak; nothing without a lung).
    Lung(LungChange),
}

/// New parameters of the test lung (see [`Action::Lung`]); `None` keeps the current value.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LungChange {
    /// Compliance, mL/cmH₂O.
    pub compliance: Option<f64>,
    /// Airway resistance, cmH₂O/(L/s).
    pub resistance: Option<f64>,
    /// PEEP valve setting, cmH₂O.
    pub peep: Option<f64>,
    /// A leak's resistance, cmH₂O/(L/s).
    pub leak: Option<f64>,
}

impl LungChange {
    /// `p` with the change applied.
    pub fn apply(&self, p: &LungParams) -> LungParams {
        LungParams {
            compliance: self.compliance.unwrap_or(p.compliance),
            resistance: self.resistance.unwrap_or(p.resistance),
            peep: self.peep.unwrap_or(p.peep),
            leak: self.leak.or(p.leak),
            ..p.clone()
        }
    }
}

/// The closed-loop bench: the simulated MCU running the firmware, its UART transcript, a serial
/// line into its USART0 ([`crate::uart`]), the simulated SFM3300 on its TWI bus and the blower
/// model on its PWM pin, with the timing meter (see the module docs). Time is the core's cycle counter; [`Bench::time_s`] in seconds.
pub struct Bench {
    /// The simulated MCU.
    pub machine: Machine,
    /// The simulated sensor's shared state.
    pub sensor: Rc<RefCell<SensorState>>,
    /// The I2C lines at the pin level (pull-ups, SDA held low, what the lines did).
    pub bus: Rc<RefCell<BusState>>,
    /// The blower (sub-stepped at 0.5 ms).
    pub pump: Pump,
    /// The test lung, if any (stepped with the blower).
    pub lung: Option<Lung>,
    cfg: BenchConfig,
    channel: Option<Channel>,
    uart: Rc<RefCell<Vec<UartByte>>>,
    uart_seen: usize,
    splitter: LineSplitter,
    line_start: Option<u64>,
    /// Complete UART lines so far.
    pub lines: Vec<Line>,
    /// Cycle at which each line's first byte was sent (same index as `lines`).
    pub line_starts: Vec<u64>,
    /// PWM changes (one entry per change seen at a plant step).
    pub duty_log: Vec<DutyChange>,
    /// 10 ms plant samples.
    pub plant_log: Vec<PlantSample>,
    next_step: u64,
    step_cycles: u64,
    substep: usize,
    schedule: Vec<(u64, Action)>,
    ticks: TickMeter,
    halted: Option<Halt>,
    /// The serial line into USART0 and its schedule.
    serial: SerialLine,
    uart_in: UartInput,
    /// The exhalation valve as the pin drives it now.
    valve: Valve,
    /// `(cycle, valve)` of every change of the valve seen at a plant step.
    pub valve_log: Vec<(u64, Valve)>,
    /// Every breath the lung saw (a closing of the valve to the next).
    pub breaths: Vec<BreathTruth>,
    /// Actions due at a breath: `(breath number from 1, delay after its closing in s,
    /// action)`.
    at_breath: Vec<(usize, f64, Action)>,
}

impl std::fmt::Debug for Bench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bench")
            .field("cycle", &self.machine.cycle())
            .field("lines", &self.lines.len())
            .finish()
    }
}

impl Bench {
    /// Loads the firmware, attaches sensor and pump, programs the EEPROM; the core is at reset.
    pub fn new(cfg: BenchConfig) -> Result<Self, String> {
        let mut machine = Machine::new("atmega2560", cfg.frequency, &cfg.elf)?;
        for (off, bytes) in &cfg.eeprom {
            machine.set_eeprom(*off, bytes)?;
        }
        let clock = Rc::new(Cell::new(0));
        let sensor = Rc::new(RefCell::new(SensorState::new(
            Sfm3300::new(cfg.sensor.clone(), cfg.seed),
            u64::from(cfg.frequency) / 2_000,
        )));
        machine.attach_twi(
            Box::new(Sfm3300Slave {
                state: sensor.clone(),
                clock: clock.clone(),
            }),
            clock,
        )?;
        let bus = bus::attach(&mut machine)?;
        let mut p = cfg.pump.clone();
        p.ts_s /= SUBSTEPS as f64;
        p.delay_samples *= SUBSTEPS;
        let pump = Pump::new(p);
        // The pump channel's PWM registers; with no channel configured, every 16-bit channel's.
        let channels: Vec<Channel> = match cfg.pwm {
            Some(c) => vec![c],
            None => Channel::all().collect(),
        };
        let targets: Vec<u16> = channels
            .iter()
            .flat_map(|c| [c.ocr_addr(), c.tccra_addr()])
            .collect();
        let pwm_sites = machine.sts_sites(&targets);
        let ticks = TickMeter::new(
            cfg.tick_vector,
            cfg.tick_vector.map(|v| machine.watch_vector(v)),
            pwm_sites,
        );
        let step_cycles = u64::from(cfg.frequency) / 2_000;
        let uart_in = machine.uart_input('0')?;
        if cfg.uart_timing == UartTiming::Chip {
            machine.uart_chip_timing('0')?;
        }
        Ok(Self {
            serial: SerialLine::new(cfg.frequency, BAUD),
            uart_in,
            uart: machine.uart0(),
            machine,
            sensor,
            bus,
            pump,
            lung: cfg.lung.clone().map(Lung::new),
            channel: cfg.pwm,
            cfg,
            uart_seen: 0,
            splitter: LineSplitter::default(),
            line_start: None,
            lines: Vec::new(),
            line_starts: Vec::new(),
            duty_log: Vec::new(),
            plant_log: Vec::new(),
            next_step: step_cycles,
            step_cycles,
            substep: 0,
            schedule: Vec::new(),
            ticks,
            halted: None,
            valve: Valve::Open,
            valve_log: Vec::new(),
            breaths: Vec::new(),
            at_breath: Vec::new(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &BenchConfig {
        &self.cfg
    }

    /// Seconds → cycles.
    pub fn cycles(&self, seconds: f64) -> u64 {
        (seconds * f64::from(self.cfg.frequency)).round() as u64
    }

    /// Core clock, Hz.
    pub fn frequency(&self) -> u32 {
        self.cfg.frequency
    }

    /// Simulated time so far, seconds.
    pub fn time_s(&self) -> f64 {
        self.machine.cycle() as f64 / f64::from(self.cfg.frequency)
    }

    /// Schedules `action` at simulated time `at_s` (seconds since reset).
    pub fn schedule(&mut self, at_s: f64, action: Action) {
        let c = self.cycles(at_s);
        self.schedule.push((c, action));
        self.schedule.sort_by_key(|(c, _)| *c);
    }

    /// Schedules `action` `delay_s` seconds after the valve closes for breath `breath` (from
    /// 1: the first closing the bench sees). A delay of 0 acts at the breath boundary, half
    /// the inspiratory time mid-inspiration.
    pub fn at_breath(&mut self, breath: usize, delay_s: f64, action: Action) {
        self.at_breath.push((breath, delay_s, action));
    }

    /// Applies `action` now.
    pub fn apply(&mut self, action: Action) {
        match action {
            Action::Sensor(f) => self.sensor.borrow_mut().fault = f,
            Action::Stall(s) => self.pump.set_stalled(s),
            Action::HoldSda(h) => self.bus.borrow_mut().arm(h),
            Action::Lung(c) => {
                if let Some(l) = &mut self.lung {
                    let p = c.apply(l.params());
                    l.set_params(p);
                }
            }
        }
    }

    /// The exhalation valve on its pin now: closed when the pin is an output driven high.
    pub fn valve_now(&self) -> Valve {
        let Some((port, bit)) = self.cfg.valve_pin else {
            return Valve::Open;
        };
        let m = &self.machine;
        let ddr = pwm::ddr_addr(port).map_or(0, |a| m.data(a));
        let out = pwm::ddr_addr(port).map_or(0, |a| m.data(a + 1));
        if ddr & out & (1 << bit) != 0 {
            Valve::Closed
        } else {
            Valve::Open
        }
    }

    /// The valve at this plant step: its changes logged, a closing starting a breath (and the
    /// actions due at it), the breath's truth kept up to date.
    fn valve_step(&mut self) -> Valve {
        let v = self.valve_now();
        let cycle = self.machine.cycle();
        if v != self.valve {
            self.valve = v;
            self.valve_log.push((cycle, v));
            let (volume, pressure) = self
                .lung
                .as_ref()
                .map_or((0.0, 0.0), |l| (l.volume(), l.pressure()));
            match v {
                Valve::Closed => {
                    self.breaths.push(BreathTruth {
                        start: cycle,
                        open: None,
                        delivered: 0.0,
                        peep: pressure,
                        peak_pressure: 0.0,
                        peak_flow: 0.0,
                        volume_at_close: volume,
                    });
                    let n = self.breaths.len();
                    let due: Vec<(f64, Action)> = self
                        .at_breath
                        .iter()
                        .filter(|(k, _, _)| *k == n)
                        .map(|&(_, d, a)| (d, a))
                        .collect();
                    for (delay, action) in due {
                        let at = cycle + self.cycles(delay);
                        self.schedule.push((at, action));
                    }
                    self.schedule.sort_by_key(|(c, _)| *c);
                }
                Valve::Open => {
                    if let Some(b) = self.breaths.last_mut() {
                        b.open = Some(cycle);
                        b.delivered = volume - b.volume_at_close;
                    }
                }
            }
        }
        v
    }

    /// Duty on the blower's pin now (0..1) and the raw registers.
    pub fn duty_now(&mut self) -> DutyChange {
        let m = &self.machine;
        if self.channel.is_none() {
            self.channel = Channel::find_active(m);
        }
        let cycle = m.cycle();
        let Some(ch) = self.channel else {
            return DutyChange {
                cycle,
                fraction: 0.0,
                ocr: 0,
                top: 0,
                connected: false,
            };
        };
        match ch.duty(m) {
            Some(d) => DutyChange {
                cycle,
                fraction: d.fraction,
                ocr: d.ocr,
                top: d.top,
                connected: true,
            },
            None => {
                // Disconnected: the pin drives its PORT bit if it is an output.
                let (port, bit) = ch.pin();
                let ddr = pwm::ddr_addr(port).map_or(0, |a| m.data(a));
                let portv = pwm::ddr_addr(port).map_or(0, |a| m.data(a + 1));
                let high = ddr & portv & (1 << bit) != 0;
                DutyChange {
                    cycle,
                    fraction: if high { 1.0 } else { 0.0 },
                    ocr: 0,
                    top: 0,
                    connected: false,
                }
            }
        }
    }

    fn plant_step(&mut self) {
        while let Some(&(c, a)) = self.schedule.first() {
            if c > self.machine.cycle() {
                break;
            }
            self.schedule.remove(0);
            self.apply(a);
        }
        let d = self.duty_now();
        let changed = self.duty_log.last().is_none_or(|l| {
            l.ocr != d.ocr
                || l.top != d.top
                || l.connected != d.connected
                || l.fraction != d.fraction
        });
        if changed {
            self.duty_log.push(d);
        }
        let valve = self.valve_step();
        let open = self.pump.step(d.fraction);
        let flow = match &mut self.lung {
            Some(lung) => {
                let p = self.pump.params();
                lung.step(valve, open, p.shutoff_of_speed(self.pump.speed()), p.ts_s)
            }
            None => open,
        };
        if let Some(b) = self.breaths.last_mut() {
            let pressure = self.lung.as_ref().map_or(0.0, Lung::airway_pressure);
            b.peak_pressure = b.peak_pressure.max(pressure);
            if b.open.is_none() {
                b.peak_flow = b.peak_flow.max(flow);
            }
        }
        self.sensor.borrow_mut().flow_slm = flow;
        self.substep += 1;
        if self.substep % SUBSTEPS == 0 {
            self.plant_log.push(PlantSample {
                cycle: d.cycle,
                duty: d.fraction,
                flow,
            });
        }
    }

    fn drain_uart(&mut self) -> usize {
        let n = self.uart.borrow().len();
        if n == self.uart_seen {
            return 0;
        }
        let bytes: Vec<UartByte> = self.uart.borrow()[self.uart_seen..].to_vec();
        self.uart_seen = n;
        let mut lines = 0;
        for b in bytes {
            if self.line_start.is_none() && b.byte != b'\n' && b.byte != b'\r' {
                self.line_start = Some(b.cycle);
            }
            if let Some(l) = self.splitter.push(b.cycle, b.byte) {
                self.line_starts
                    .push(self.line_start.take().unwrap_or(b.cycle));
                self.lines.push(l);
                lines += 1;
            }
        }
        lines
    }

    /// Runs until simulated time `until_s` (seconds since reset), or until `stop` returns true
    /// for a new line (checked at line ends). Returns how the run ended.
    pub fn run_until(&mut self, until_s: f64, mut stop: impl FnMut(&Line) -> bool) -> RunEnd {
        let target = self.cycles(until_s);
        if let Some(h) = self.halted {
            return RunEnd::Halted(h);
        }
        while self.machine.cycle() < target {
            self.serial.deliver(self.machine.cycle(), &self.uart_in);
            let chunk_end = self
                .next_step
                .min(target)
                .min(self.serial.next_due().unwrap_or(u64::MAX));
            while self.machine.cycle() < chunk_end {
                let executed = self.machine.pc();
                let h = self.machine.step();
                self.ticks.after_step(
                    self.machine.cycle(),
                    self.machine.pc(),
                    self.machine.sp(),
                    self.machine.interrupts_enabled(),
                    executed,
                );
                if h != Halt::Reached {
                    self.halted = Some(h);
                    self.drain_uart();
                    return RunEnd::Halted(h);
                }
            }
            if self.machine.cycle() >= self.next_step {
                self.next_step += self.step_cycles;
                self.plant_step();
            }
            let new = self.drain_uart();
            if new > 0 {
                let first = self.lines.len() - new;
                let now = self.machine.cycle();
                for l in &self.lines[first..] {
                    self.serial.on_line(l, now);
                }
                for i in first..self.lines.len() {
                    if stop(&self.lines[i]) {
                        return RunEnd::Line(i);
                    }
                }
            }
        }
        RunEnd::Time
    }

    /// Runs for `seconds` more of simulated time.
    pub fn run_for(&mut self, seconds: f64) -> RunEnd {
        let t = self.time_s() + seconds;
        self.run_until(t, |_| false)
    }

    /// Sends `bytes` on the serial line into USART0 from simulated time `at_s` (seconds since
    /// reset) on, or as soon as the line is free (see [`crate::uart`]). A command line needs its
    /// `\n`.
    pub fn send_at(&mut self, at_s: f64, bytes: impl Into<Vec<u8>>) -> SendId {
        let at = self.cycles(at_s);
        self.serial.send_at(at, bytes)
    }

    /// Sends `bytes` from core cycle `at` on (or as soon as the line is free).
    pub fn serial_at_cycle(&mut self, at: u64, bytes: impl Into<Vec<u8>>) -> SendId {
        self.serial.send_at(at, bytes)
    }

    /// Sends `bytes` from now on (or as soon as the line is free).
    pub fn send_now(&mut self, bytes: impl Into<Vec<u8>>) -> SendId {
        let at = self.machine.cycle();
        self.serial.send_at(at, bytes)
    }

    /// Sends `bytes` `delay_s` seconds after the end of the first UART line from now on whose
    /// text `matches` accepts (checked as lines complete while the bench runs).
    pub fn send_after(
        &mut self,
        matches: impl FnMut(&str) -> bool + 'static,
        delay_s: f64,
        bytes: impl Into<Vec<u8>>,
    ) -> SendId {
        let delay = self.cycles(delay_s);
        self.serial.send_after(matches, delay, bytes)
    }

    /// The transmission `id` (its bytes, when each went out, bytes lost).
    pub fn sent(&self, id: SendId) -> &Transmission {
        self.serial.get(id)
    }

    /// The serial line into USART0.
    pub fn serial(&self) -> &SerialLine {
        &self.serial
    }

    /// Tick timings measured so far (empty until the idle loop has been learned, i.e. the first
    /// 64 ticks).
    pub fn ticks(&self) -> &[TickTiming] {
        self.ticks.ticks()
    }

    /// Learned idle wait: (instruction address in bytes, stack pointer) pairs, if any.
    pub fn idle_pcs(&self) -> Option<&[(u32, u16)]> {
        self.ticks.idle()
    }

    /// Cycles spent in the idle wait so far.
    pub fn idle_cycles(&self) -> u64 {
        self.ticks.idle_cycles()
    }

    /// The tick vector watched.
    pub fn tick_vector(&self) -> Option<u8> {
        self.ticks.vector()
    }

    /// The transcript for a failure message: every line but those starting with one of
    /// `leave_out` (e.g. `"RES "`, `"TRACK "`), each as `  [time s] text` on its own line.
    pub fn transcript(&self, leave_out: &[&str]) -> String {
        let per_s = f64::from(self.cfg.frequency);
        self.lines
            .iter()
            .filter(|l| !leave_out.iter().any(|p| l.text.starts_with(p)))
            .map(|l| format!("  [{:8.3} s] {}\n", l.cycle as f64 / per_s, l.text))
            .collect()
    }

    /// Lines whose keyword is `kw`, with their index.
    pub fn find_lines<'a>(&'a self, kw: &'a str) -> impl Iterator<Item = (usize, &'a Line)> + 'a {
        self.lines
            .iter()
            .enumerate()
            .filter(move |(_, l)| l.text.split_whitespace().next() == Some(kw))
    }

    /// Stack high-water mark from SRAM, bytes: the firmware paints the free SRAM between
    /// `__heap_start` (end of static data) and the stack with `0xAA` at start-up; the bytes from
    /// RAMEND down to the lowest overwritten one were used by the stack. `None` if the ELF has
    /// no `__heap_start` symbol.
    pub fn stack_used(&self) -> Option<u32> {
        let start = self.machine.symbol("__heap_start")?.addr & 0xFFFF;
        let ramend = u32::from(self.machine.ramend());
        let mut free = 0;
        let mut a = start;
        while a <= ramend && self.machine.data(a as u16) == 0xAA {
            free += 1;
            a += 1;
        }
        Some(ramend + 1 - start - free)
    }

    /// Static RAM end (`__heap_start`, data-space address), if the ELF names it.
    pub fn heap_start(&self) -> Option<u32> {
        Some(self.machine.symbol("__heap_start")?.addr & 0xFFFF)
    }

    /// Whether the core stopped (crash or exit).
    pub fn halted(&self) -> Option<Halt> {
        self.halted
    }

    /// Duty change in effect at `cycle` (the last one logged at or before it).
    pub fn duty_at(&self, cycle: u64) -> Option<&DutyChange> {
        let i = self.duty_log.partition_point(|d| d.cycle <= cycle);
        i.checked_sub(1).map(|i| &self.duty_log[i])
    }
}

/// How [`Bench::run_until`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunEnd {
    /// Reached the time limit.
    Time,
    /// The stop predicate accepted line `n`.
    Line(usize),
    /// The core crashed or stopped.
    Halted(Halt),
}
