//! The bench: the emulated STM32F411 running the image, wired to the simulated plant, closed
//! loop: firmware ⇄ SFM3300 on I2C1 ⇄ blower (and test lung) driven by TIM3 channel 1's duty
//! on PA6, as `simavr-harness`'s bench wires the ATmega2560.
//!
//! Every 0.5 ms of emulated time (the SFM3300's update period) the bench reads the duty the
//! timer drives on the pin, steps `pump_sim::Pump` (its 100 Hz parameters sub-stepped 20×) and
//! the lung by 0.5 ms with the exhalation valve PB0 drives (high = closed; low or not an
//! output = open, the driver's pull-down), and hands the flow to the sensor. It splits USART1's output into lines,
//! plays bytes into USART1's receiver at 115 200 baud, and applies scheduled actions (sensor
//! faults, SDA held low, a stalled blower, a cut PWM line, a reset, a power cut).

use std::cell::RefCell;
use std::path::PathBuf;
use std::rc::Rc;

use pump_sim::{Lung, LungParams, Pump, PumpParams, Sfm3300, Sfm3300Params, Valve};
use ridge_pump_firmware::flash_store::SECTORS;

use crate::bus::{BusSlave, Lines, SdaHold};
use crate::machine::Machine;
use crate::periph::flash::{self, EraseCut};
use crate::periph::i2c::BusFault;
use crate::periph::rcc::ResetCause;
use crate::periph::{Time, PS_PER_S};
use crate::sensor::{Fault, SensorState, Sfm3300Slave, UPDATE_PS};
use crate::transcript::Line;

/// Plant sub-steps per 10 ms sample (0.5 ms each).
pub const SUBSTEPS: usize = 20;
/// One plant sub-step, ps.
pub const STEP_PS: Time = PS_PER_S / 2_000;
/// The console's baud rate (the image's `BAUD`).
pub const BAUD: u64 = 115_200;
/// One 8N1 frame at [`BAUD`] (10 bits), ps.
pub const FRAME_PS: Time = PS_PER_S * 10 / BAUD;

/// Seconds → ps.
pub fn ps(seconds: f64) -> Time {
    (seconds * PS_PER_S as f64).round() as Time
}

/// ps → seconds.
pub fn secs(t: Time) -> f64 {
    t as f64 / PS_PER_S as f64
}

/// Bench settings.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    /// Firmware ELF.
    pub elf: PathBuf,
    /// Blower (100 Hz parameters; sub-stepped).
    pub pump: PumpParams,
    /// Test lung, `None` for an open outlet.
    pub lung: Option<LungParams>,
    /// Sensor error model.
    pub sensor: Sfm3300Params,
    /// Sensor noise seed.
    pub seed: u64,
    /// Flash memory to start from (a previous run's, kept across the power cycle), instead of
    /// the freshly flashed image.
    pub flash: Option<Vec<u8>>,
}

impl BenchConfig {
    /// Default blower, open outlet, default sensor, seed 1, freshly flashed.
    pub fn new(elf: impl Into<PathBuf>) -> Self {
        BenchConfig {
            elf: elf.into(),
            pump: PumpParams::default(),
            lung: None,
            sensor: Sfm3300Params::default(),
            seed: 1,
            flash: None,
        }
    }
}

/// A scheduled change.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Set the sensor fault.
    Sensor(Fault),
    /// Block or free the rotor.
    Stall(bool),
    /// Cut (`true`) or mend the pump's PWM line: the blower sees duty 0 whatever the pin
    /// drives (a dead driver or wire).
    PwmLineCut(bool),
    /// Reset the chip by this cause: the NRST pin, a watchdog expiry (as the IWDG's own would),
    /// a brown-out, or a power cycle (RAM lost, the backup domain too).
    Reset(ResetCause),
    /// Cut the power after this many more flash program accesses, then power up again.
    PowerCutAfterProgram(usize),
    /// Cut the power during the next sector erase, this far through it (see
    /// [`crate::periph::flash::EraseCut`]), then power up again.
    PowerCutInErase(EraseCut),
    /// A fault on the I2C bus during the next byte (BERR, or ARLO: another master).
    Bus(BusFault),
    /// The sensor holds SDA low from the end of the next STOP condition on ([`crate::bus`]).
    HoldSda(SdaHold),
}

/// The duty on the pump's pin, seen at a plant step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DutyChange {
    /// Time of the plant step that saw it.
    pub at: Time,
    /// Duty fraction 0..1.
    pub fraction: f64,
    /// `TIM3_CCR1`.
    pub ccr: u32,
    /// `TIM3_ARR + 1`.
    pub period: u32,
}

/// One 10 ms plant sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantSample {
    /// Time.
    pub at: Time,
    /// Duty 0..1.
    pub duty: f64,
    /// True flow, slm.
    pub flow: f64,
}

/// How [`Bench::run_until`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunEnd {
    /// Reached the time.
    Time,
    /// The predicate accepted line `n`.
    Line(usize),
}

/// The closed-loop bench.
pub struct Bench {
    /// The emulated MCU.
    pub machine: Machine,
    /// The sensor's shared state.
    pub sensor: Rc<RefCell<SensorState>>,
    /// The I2C lines at the pins.
    pub bus: Rc<RefCell<Lines>>,
    /// The blower.
    pub pump: Pump,
    /// The lung, if any.
    pub lung: Option<Lung>,
    cfg: BenchConfig,
    /// Complete lines from USART1.
    pub lines: Vec<Line>,
    /// PWM changes seen at plant steps.
    pub duty_log: Vec<DutyChange>,
    /// Exhalation valve changes seen at plant steps (time, new state); open before the first.
    pub valve_log: Vec<(Time, Valve)>,
    /// 10 ms plant samples.
    pub plant_log: Vec<PlantSample>,
    next_step: Time,
    substep: usize,
    pwm_cut: bool,
    schedule: Vec<(Time, Action)>,
    sent_seen: usize,
    partial: Vec<u8>,
    partial_start: Option<(Time, u64)>,
    /// When the receive line is next free, ps.
    rx_free: Time,
}

impl std::fmt::Debug for Bench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bench")
            .field("now", &self.machine.now())
            .field("lines", &self.lines.len())
            .finish()
    }
}

impl Bench {
    /// Loads the image, attaches sensor and plant; the core is at reset.
    pub fn new(cfg: BenchConfig) -> Result<Self, String> {
        let sensor = Rc::new(RefCell::new(SensorState::new(
            Sfm3300::new(cfg.sensor.clone(), cfg.seed),
            UPDATE_PS,
        )));
        let bus = Rc::new(RefCell::new(Lines::default()));
        let slave = BusSlave {
            inner: Box::new(Sfm3300Slave {
                state: sensor.clone(),
            }),
            lines: bus.clone(),
        };
        let mut machine = Machine::new(&cfg.elf, Box::new(slave))?;
        if let Some(mem) = &cfg.flash {
            machine.load_flash(mem)?;
        }
        let mut p = cfg.pump.clone();
        p.ts_s /= SUBSTEPS as f64;
        p.delay_samples *= SUBSTEPS;
        Ok(Bench {
            machine,
            sensor,
            bus,
            pump: Pump::new(p),
            lung: cfg.lung.clone().map(Lung::new),
            cfg,
            lines: Vec::new(),
            duty_log: Vec::new(),
            valve_log: Vec::new(),
            plant_log: Vec::new(),
            next_step: STEP_PS,
            substep: 0,
            pwm_cut: false,
            schedule: Vec::new(),
            sent_seen: 0,
            partial: Vec::new(),
            partial_start: None,
            rx_free: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &BenchConfig {
        &self.cfg
    }

    /// Emulated time, seconds.
    pub fn time_s(&self) -> f64 {
        secs(self.machine.now())
    }

    /// Schedules `action` at `at_s` seconds.
    pub fn schedule(&mut self, at_s: f64, action: Action) {
        self.schedule.push((ps(at_s), action));
        self.schedule.sort_by_key(|a| a.0);
    }

    /// Applies `action` now.
    pub fn apply(&mut self, action: Action) -> Result<(), String> {
        match action {
            Action::Sensor(f) => self.sensor.borrow_mut().fault = f,
            Action::Stall(s) => self.pump.set_stalled(s),
            Action::PwmLineCut(c) => self.pwm_cut = c,
            Action::Reset(ResetCause::PowerOn) => self.machine.power_cycle()?,
            Action::Reset(cause) => self.machine.reset(cause)?,
            Action::PowerCutAfterProgram(n) => {
                let done = self.machine.chip().flash.programmed.len();
                self.machine.core_mut().power_cut_after = Some(done + n);
            }
            Action::PowerCutInErase(cut) => self.machine.chip_mut().flash.erase_cut = Some(cut),
            Action::Bus(f) => self.machine.chip_mut().i2c1.inject(f),
            Action::HoldSda(hold) => self.bus.borrow_mut().arm(hold),
        }
        Ok(())
    }

    /// Plays `bytes` into USART1's receiver from `at_s` seconds on (or when the line is
    /// free), back to back at 115 200 baud 8N1; returns when the last stop bit ends, ps.
    pub fn send_at(&mut self, at_s: f64, bytes: &[u8]) -> Time {
        let mut t = ps(at_s).max(self.rx_free).max(self.machine.now());
        for &b in bytes {
            t += FRAME_PS;
            self.machine.chip_mut().usart1.receive_at(t, b);
        }
        self.rx_free = t;
        t
    }

    /// The duty on PA6 now: TIM3 channel 1 when the pin is in alternate function 2, else
    /// the pin's output level.
    pub fn duty_now(&self) -> DutyChange {
        let chip = self.machine.chip();
        let at = self.machine.now();
        let (ccr, period) = chip.tim3.ch1_counts();
        let fraction = match chip.gpioa.mode(6) {
            2 if chip.gpioa.alternate(6) == 2 => chip.tim3.duty_ch1().unwrap_or(0.0),
            1 => f64::from(u8::from(chip.gpioa.read_odr() >> 6 & 1 != 0)),
            _ => 0.0,
        };
        DutyChange {
            at,
            fraction,
            ccr,
            period,
        }
    }

    /// The exhalation valve PB0 drives now (docs/boards.md): closed while PB0 is a
    /// general-purpose output with its `ODR` bit 1; open otherwise (driven low, or an input that
    /// the valve driver's pull-down holds low).
    pub fn valve_now(&self) -> Valve {
        let gpiob = &self.machine.chip().gpiob;
        if gpiob.mode(0) == 1 && gpiob.read_odr() & 1 != 0 {
            Valve::Closed
        } else {
            Valve::Open
        }
    }

    fn plant_step(&mut self) -> Result<(), String> {
        while let Some(&(t, a)) = self.schedule.first() {
            if t > self.machine.now() {
                break;
            }
            self.schedule.remove(0);
            self.apply(a)?;
        }
        let d = self.duty_now();
        if self
            .duty_log
            .last()
            .is_none_or(|l| l.fraction != d.fraction || l.ccr != d.ccr || l.period != d.period)
        {
            self.duty_log.push(d);
        }
        let valve = self.valve_now();
        if self.valve_log.last().map_or(Valve::Open, |&(_, v)| v) != valve {
            self.valve_log.push((self.machine.now(), valve));
        }
        let open = self.pump.step(if self.pwm_cut { 0.0 } else { d.fraction });
        let flow = match &mut self.lung {
            Some(lung) => {
                let p = self.pump.params();
                lung.step(valve, open, p.shutoff_of_speed(self.pump.speed()), p.ts_s)
            }
            None => open,
        };
        self.sensor.borrow_mut().flow_slm = flow;
        self.substep += 1;
        if self.substep % SUBSTEPS == 0 {
            self.plant_log.push(PlantSample {
                at: d.at,
                duty: d.fraction,
                flow,
            });
        }
        Ok(())
    }

    /// Moves the bytes USART1 sent into lines; returns how many lines completed. A line cut
    /// by a reset ends there (its text as far as it was sent), so that the next boot's first
    /// line starts a line of its own.
    fn drain(&mut self) -> usize {
        let sent = &self.machine.chip().usart1.sent;
        let resets = &self.machine.resets;
        let mut new = 0;
        for s in &sent[self.sent_seen..] {
            if let Some((start, start_instr)) = self.partial_start {
                if let Some(r) = resets.iter().find(|r| r.at > start && r.at <= s.start) {
                    self.lines.push(Line {
                        text: String::from_utf8_lossy(&self.partial).into_owned(),
                        start,
                        start_instr,
                        end: r.at,
                    });
                    self.partial.clear();
                    self.partial_start = None;
                    new += 1;
                }
            }
            match s.byte {
                b'\n' => {
                    let (start, start_instr) =
                        self.partial_start.take().unwrap_or((s.start, s.instr));
                    self.lines.push(Line {
                        text: String::from_utf8_lossy(&self.partial).into_owned(),
                        start,
                        start_instr,
                        end: s.end,
                    });
                    self.partial.clear();
                    new += 1;
                }
                b'\r' => {}
                b => {
                    if self.partial_start.is_none() {
                        self.partial_start = Some((s.start, s.instr));
                    }
                    self.partial.push(b);
                }
            }
        }
        self.sent_seen = sent.len();
        new
    }

    /// Runs until `until_s` seconds, or until `stop` accepts a new line.
    pub fn run_until(
        &mut self,
        until_s: f64,
        mut stop: impl FnMut(&Line) -> bool,
    ) -> Result<RunEnd, String> {
        let target = ps(until_s);
        while self.machine.now() < target {
            let to = self.next_step.min(target);
            self.machine.run_until(to)?;
            while self.machine.now() >= self.next_step {
                self.next_step += STEP_PS;
                self.plant_step()?;
            }
            let new = self.drain();
            let first = self.lines.len() - new;
            for i in first..self.lines.len() {
                if stop(&self.lines[i]) {
                    return Ok(RunEnd::Line(i));
                }
            }
        }
        Ok(RunEnd::Time)
    }

    /// Runs `seconds` more.
    pub fn run_for(&mut self, seconds: f64) -> Result<RunEnd, String> {
        let t = self.time_s() + seconds;
        self.run_until(t, |_| false)
    }

    /// Lines whose keyword is `kw`.
    pub fn find<'a>(&'a self, kw: &'a str) -> impl Iterator<Item = &'a Line> + 'a {
        self.lines.iter().filter(move |l| l.keyword() == kw)
    }

    /// The duty change in effect at `t`.
    pub fn duty_at(&self, t: Time) -> Option<&DutyChange> {
        let i = self.duty_log.partition_point(|d| d.at <= t);
        i.checked_sub(1).map(|i| &self.duty_log[i])
    }

    /// The flash memory now (to start another bench from, as after a power cycle).
    pub fn flash(&self) -> Vec<u8> {
        self.machine.chip().flash.mem.clone()
    }

    /// The flash sectors the image keeps its record in (`flash_store::SECTORS`: 6 and 7),
    /// as they are now.
    pub fn store(&self) -> [Vec<u8>; 2] {
        let mem = &self.machine.chip().flash.mem;
        SECTORS.map(|(n, offset)| {
            let (start, len) = flash::SECTORS[usize::from(n)];
            assert_eq!(start, offset, "sector {n}");
            mem[start as usize..(start + len) as usize].to_vec()
        })
    }

    /// Whether the store's sectors hold anything but 0xFF.
    pub fn store_used(&self) -> bool {
        self.store().iter().flatten().any(|&b| b != flash::ERASED)
    }
}
