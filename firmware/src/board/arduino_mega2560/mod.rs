//! ATmega2560 (Arduino Mega 2560, 16 MHz) peripherals on `avr-device`: thin embedded-hal 1.0 /
//! `ufmt` adapters of our own (avr-hal is not on crates.io).
//!
//! | module | peripheral | Arduino pins |
//! |---|---|---|
//! | [`twi`] | TWI, I2C master (`embedded_hal::i2c::I2c`) | D20 SDA, D21 SCL |
//! | [`pwm`] | Timer4 OC4A, 20 kHz (`embedded_hal::pwm::SetDutyCycle`) | D6 |
//! | [`valve`] | exhalation valve, digital output (high = closed) | D22 |
//! | [`usart`] | USART0 115200 8N1, TX (`ufmt::uWrite`) | D1 TX (USB serial) |
//! | [`timer`] | Timer3 CTC, 100 Hz tick interrupt | — |
//! | [`eeprom`] | EEPROM, background record writer | — |
//! | [`watchdog`] | WDT 0.5 s, reset cause | — |
//! | [`stack`] | stack painting and high-water mark | — |

pub mod eeprom;
pub mod pwm;
pub mod stack;
pub mod timer;
pub mod twi;
pub mod usart;
pub mod valve;
pub mod watchdog;

/// CPU clock of the Arduino Mega 2560 (16 MHz crystal).
pub const F_CPU: u32 = 16_000_000;
