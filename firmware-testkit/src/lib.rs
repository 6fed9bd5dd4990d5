//! Fakes of what a board gives the firmware, for host tests of the 100 Hz loop
//! (`ridge_pump_firmware::app`) and the drivers: an SFM3300 on an embedded-hal I2C bus
//! ([`FakeSensor`]), a PWM channel ([`FakePwm`]), a UART that collects the lines ([`Uart`]) and
//! a [`FakeBoard`] with a simulated clock, a watchdog counter, a record store and a console
//! input. They share one [`World`]: the plant ([`Plant`]: the synthetic plant of the firmware's
//! tests, or `pump_sim::Rig`), the clock and the fault switches.
//!
//! The fake sensor frames each word with pump-sim's CRC-8 ([`pump_sim::sfm3300::frame`], the
//! datasheet's polynomial 0x31 and init 0x00, pinned there on its vectors), not with the
//! driver's own `crc8`, so the driver's check is tested against an independent
//! implementation.
//!
//! Time: every [`Board::poll_tick`] costs [`POLL_US`] of simulated time, a tick is
//! [`TICK_US`]; at each tick boundary the plant runs one interval at the duty the PWM holds.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};
use embedded_hal::pwm::{self, SetDutyCycle};
use ridge_pump_firmware::app::{Board, Console};
use ridge_pump_firmware::sfm3300::ADDRESS;
use ridge_pump_firmware::units::{DUTY_FULL_SCALE, FLOW_OFFSET};

/// Simulated time one [`Board::poll_tick`] call costs, µs.
pub const POLL_US: u64 = 500;
/// Tick period, µs (100 Hz).
pub const TICK_US: u64 = 10_000;
/// Polls after [`Board::save`] until the fake store reports the write finished.
pub const STORE_TICKS: u32 = 30;

/// The SFM3300's command "start continuous measurement" (datasheet: `0x1000`).
const START: [u8; 2] = [0x10, 0x00];

/// What the fake sensor measures: a plant run one sample interval at a time.
pub trait Plant {
    /// Applies `duty` (1/10 000 of full scale) for one interval; the SFM3300 word at its end.
    fn step_word(&mut self, duty: u16) -> u16;
}

impl Plant for pump_sim::Rig {
    fn step_word(&mut self, duty: u16) -> u16 {
        self.step(duty)
    }
}

/// Everything the fakes share: the plant, the clock, what the sensor and the PWM hold, and
/// the fault switches. `P` needs no [`Plant`] where nothing ticks (a PWM alone).
pub struct World<P> {
    /// The plant.
    pub plant: P,
    /// Simulated time, µs.
    pub clock: u64,
    /// Clock at the last tick boundary handed out by `poll_tick`.
    pub last_boundary: u64,
    /// The latest reading, counts (`word − 32768`, 1/120 slm), advanced once per tick
    /// boundary.
    pub reading: i16,
    /// The PWM channel's resolution (`max_duty_cycle`).
    pub pwm_max: u16,
    /// PWM counts written last.
    pub pwm: u16,
    /// `(clock, counts)` of every PWM write.
    pub pwm_log: Vec<(u64, u16)>,
    /// The PWM channel refuses writes while this is set.
    pub pwm_broken: bool,
    /// The sensor acknowledges nothing (absent or dead) while this is set.
    pub sensor_dead: bool,
    /// The sensor acknowledged `start continuous measurement`.
    pub started: bool,
    /// The first frame after the start is not a measurement (`0xFFFF`): served once.
    pub first_frame: bool,
    /// Extra simulated time of the next sensor read, µs (a slow tick), then 0.
    pub next_read_us: u64,
    /// `pet` calls.
    pub pets: u64,
    /// Largest simulated time between two `pet` calls, µs.
    pub longest_unpetted: u64,
    /// Clock of the last `pet`, µs.
    pub last_pet: u64,
}

/// The world as the fakes hold it.
pub type Shared<P> = Rc<RefCell<World<P>>>;

/// A world at time 0 around `plant`, with a PWM channel of `pwm_max` counts, nothing written
/// and no fault.
pub fn world<P>(plant: P, pwm_max: u16) -> Shared<P> {
    Rc::new(RefCell::new(World {
        plant,
        clock: 0,
        last_boundary: 0,
        reading: 0,
        pwm_max,
        pwm: 0,
        pwm_log: Vec::new(),
        pwm_broken: false,
        sensor_dead: false,
        started: false,
        first_frame: true,
        next_read_us: 0,
        pets: 0,
        longest_unpetted: 0,
        last_pet: 0,
    }))
}

impl<P> World<P> {
    /// The PWM counts written, in order.
    pub fn pwm_writes(&self) -> Vec<u16> {
        self.pwm_log.iter().map(|&(_, c)| c).collect()
    }
}

/// The SFM3300 at [`ADDRESS`] on the bus: `0x1000` starts it, every read returns the latest
/// reading as `[MSB, LSB, CRC]` (the datasheet's frame, by pump-sim). Nothing is acknowledged
/// before the start or while [`World::sensor_dead`] is set.
pub struct FakeSensor<P>(pub Shared<P>);

impl<P> ErrorType for FakeSensor<P> {
    type Error = ErrorKind;
}

impl<P> I2c for FakeSensor<P> {
    fn transaction(&mut self, address: u8, ops: &mut [Operation<'_>]) -> Result<(), ErrorKind> {
        let mut w = self.0.borrow_mut();
        if w.sensor_dead || address != ADDRESS {
            return Err(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
        }
        for op in ops {
            match op {
                Operation::Write(bytes) => {
                    if *bytes == START {
                        w.started = true;
                        w.first_frame = true;
                    }
                }
                Operation::Read(buf) => {
                    if !w.started {
                        return Err(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
                    }
                    w.clock += std::mem::take(&mut w.next_read_us);
                    let word = if std::mem::take(&mut w.first_frame) {
                        0xFFFF
                    } else {
                        // |reading| ≤ 32 768: the word is 0..=65 535.
                        (i32::from(w.reading) + i32::from(FLOW_OFFSET)) as u16
                    };
                    for (b, f) in buf.iter_mut().zip(pump_sim::sfm3300::frame(word)) {
                        *b = f;
                    }
                }
            }
        }
        Ok(())
    }
}

/// A PWM channel of [`World::pwm_max`] counts that logs every write; it refuses writes while
/// [`World::pwm_broken`] is set and panics on a duty above its maximum (the embedded-hal
/// contract the pump driver must keep).
pub struct FakePwm<P>(pub Shared<P>);

impl<P> Clone for FakePwm<P> {
    fn clone(&self) -> Self {
        FakePwm(self.0.clone())
    }
}

impl FakePwm<()> {
    /// A channel of `max` counts on a world of its own (no plant: for the pump driver alone).
    pub fn alone(max: u16) -> Self {
        FakePwm(world((), max))
    }
}

impl<P> FakePwm<P> {
    /// The counts written, in order.
    pub fn writes(&self) -> Vec<u16> {
        self.0.borrow().pwm_writes()
    }

    /// Makes the channel refuse writes (`true`) or take them again.
    pub fn set_broken(&self, broken: bool) {
        self.0.borrow_mut().pwm_broken = broken;
    }
}

/// The error of a [`FakePwm`] with [`World::pwm_broken`] set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PwmBroken;

impl pwm::Error for PwmBroken {
    fn kind(&self) -> pwm::ErrorKind {
        pwm::ErrorKind::Other
    }
}

impl<P> pwm::ErrorType for FakePwm<P> {
    type Error = PwmBroken;
}

impl<P> SetDutyCycle for FakePwm<P> {
    fn max_duty_cycle(&self) -> u16 {
        self.0.borrow().pwm_max
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), PwmBroken> {
        let mut w = self.0.borrow_mut();
        assert!(duty <= w.pwm_max, "duty {duty} above max {}", w.pwm_max);
        if w.pwm_broken {
            return Err(PwmBroken);
        }
        w.pwm = duty;
        let t = w.clock;
        w.pwm_log.push((t, duty));
        Ok(())
    }
}

/// The UART: everything the loop prints.
#[derive(Clone, Default)]
pub struct Uart(pub Rc<RefCell<String>>);

impl ufmt::uWrite for Uart {
    type Error = core::convert::Infallible;
    fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
        self.0.borrow_mut().push_str(s);
        Ok(())
    }
}

impl Uart {
    /// The lines printed so far (the last one even without its terminator).
    pub fn lines(&self) -> Vec<String> {
        self.0.borrow().lines().map(str::to_owned).collect()
    }
}

/// A board whose search mode is `TICKING` (the STM32F411's `true`, the ATmega2560's
/// `false`), on the simulated clock of its [`World`].
pub struct FakeBoard<P, const TICKING: bool> {
    /// The world.
    pub w: Shared<P>,
    /// Every record handed to [`Board::save`].
    pub saves: Vec<Vec<u8>>,
    /// Polls until the write in progress finishes.
    pub store_in: Option<u32>,
    /// Polls a write takes ([`STORE_TICKS`]); `None`: a write never finishes.
    pub store_ticks: Option<u32>,
    /// What a finished write reports.
    pub store_ok: bool,
    /// Console bytes and the simulated time (µs) they arrive at.
    pub rx: VecDeque<(u64, u8)>,
    /// A receive overrun to report once the bytes before it have been read.
    pub rx_lost: bool,
    /// Free room in the transmit queue, bytes.
    pub room: usize,
    /// The console, if the board has one.
    pub console: Option<Console>,
    /// What [`Board::stack`] reports: `(used, free)` bytes.
    pub stack: Option<(u16, u16)>,
}

impl<P, const TICKING: bool> FakeBoard<P, TICKING> {
    /// A board without a console, stack figures or pending input; writes finish after
    /// [`STORE_TICKS`] polls and succeed.
    pub fn new(w: &Shared<P>) -> Self {
        FakeBoard {
            w: w.clone(),
            saves: Vec::new(),
            store_in: None,
            store_ticks: Some(STORE_TICKS),
            store_ok: true,
            rx: VecDeque::new(),
            rx_lost: false,
            room: usize::MAX,
            console: None,
            stack: None,
        }
    }

    /// The same with a console.
    pub fn with_console(w: &Shared<P>) -> Self {
        FakeBoard {
            console: Some(Console::new()),
            ..Self::new(w)
        }
    }

    /// Queues `line` to arrive `after_us` from now.
    pub fn send(&mut self, line: &str, after_us: u64) {
        let t = self.w.borrow().clock + after_us;
        self.rx.extend(line.bytes().map(|b| (t, b)));
    }
}

impl<P: Plant, const TICKING: bool> Board for FakeBoard<P, TICKING> {
    const TICK_DURING_SEARCH: bool = TICKING;

    fn poll_tick(&mut self) -> Option<u16> {
        let mut w = self.w.borrow_mut();
        w.clock += POLL_US;
        let elapsed = (w.clock - w.last_boundary) / TICK_US;
        if elapsed == 0 {
            return None;
        }
        w.last_boundary += elapsed * TICK_US;
        // The plant runs for each interval at the duty the PWM holds; the reading is the flow
        // at the end of the last one.
        for _ in 0..elapsed {
            let duty =
                (u32::from(w.pwm) * u32::from(DUTY_FULL_SCALE) / u32::from(w.pwm_max)) as u16;
            let word = w.plant.step_word(duty);
            w.reading = (i32::from(word) - i32::from(FLOW_OFFSET)) as i16;
        }
        Some(elapsed as u16)
    }

    fn pet(&mut self) {
        let mut w = self.w.borrow_mut();
        let gap = w.clock - w.last_pet;
        w.longest_unpetted = w.longest_unpetted.max(gap);
        w.last_pet = w.clock;
        w.pets += 1;
    }

    fn save(&mut self, record: &[u8]) {
        self.saves.push(record.to_vec());
        self.store_in = self.store_ticks;
    }

    fn poll_store(&mut self) -> Option<bool> {
        let left = self.store_in.as_mut()?;
        *left -= 1;
        if *left == 0 {
            self.store_in = None;
            return Some(self.store_ok);
        }
        None
    }

    fn stack(&self) -> Option<(u16, u16)> {
        self.stack
    }

    fn receive(&mut self) -> Option<u8> {
        let now = self.w.borrow().clock;
        match self.rx.front() {
            Some(&(t, b)) if t <= now => {
                self.rx.pop_front();
                Some(b)
            }
            _ => None,
        }
    }

    /// As the STM32F411's receiver: a loss is reported once the bytes received before it have
    /// been read.
    fn receive_overrun(&mut self) -> bool {
        let now = self.w.borrow().clock;
        if self.rx.front().is_some_and(|&(t, _)| t <= now) {
            return false;
        }
        std::mem::take(&mut self.rx_lost)
    }

    fn tx_room(&self) -> usize {
        self.room
    }

    fn console(&mut self) -> Option<&mut Console> {
        self.console.as_mut()
    }
}
