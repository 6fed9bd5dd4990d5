//! The peripheral models against RM0383 (and the datasheet figures it defers to): each test
//! drives a model through its registers as firmware would and checks what the manual says
//! the registers show, at the times its formulas give.

use std::cell::RefCell;
use std::rc::Rc;

use stm32_harness::periph::flash::{self, Flash};
use stm32_harness::periph::i2c::{self, Device, I2c};
use stm32_harness::periph::iwdg::{self, Iwdg};
use stm32_harness::periph::rcc::{self, Rcc, ResetCause};
use stm32_harness::periph::timer::{self, Timer};
use stm32_harness::periph::usart::{self, Usart};
use stm32_harness::periph::{Time, PS_PER_S};

const US: Time = 1_000_000;
const MS: Time = 1_000 * US;

/// A scripted I2C slave: acknowledges address 0x40, serves 0xA1, 0xB2, 0xC3, logs the bus.
#[derive(Default)]
struct Script {
    log: Vec<String>,
    next: u8,
}

#[derive(Clone, Default)]
struct Slave(Rc<RefCell<Script>>);

impl Device for Slave {
    fn start(&mut self, now: Time) {
        self.0.borrow_mut().log.push(format!("S@{}", now / US));
    }
    fn address(&mut self, addr: u8, read: bool, now: Time) -> bool {
        self.0.borrow_mut().log.push(format!(
            "A{addr:02x}{}@{}",
            if read { 'r' } else { 'w' },
            now / US
        ));
        addr == 0x40
    }
    fn write(&mut self, byte: u8, now: Time) -> bool {
        self.0
            .borrow_mut()
            .log
            .push(format!("W{byte:02x}@{}", now / US));
        true
    }
    fn read(&mut self, _now: Time) -> u8 {
        let mut s = self.0.borrow_mut();
        let b = [0xA1, 0xB2, 0xC3]
            .get(s.next as usize)
            .copied()
            .unwrap_or(0xFF);
        s.next += 1;
        b
    }
    fn read_ack(&mut self, ack: bool, now: Time) {
        self.0
            .borrow_mut()
            .log
            .push(format!("{}@{}", if ack { "ACK" } else { "NACK" }, now / US));
    }
    fn stop(&mut self, now: Time) {
        self.0.borrow_mut().log.push(format!("P@{}", now / US));
    }
    fn holds_sda(&self, _now: Time) -> bool {
        false
    }
}

/// I2C1 at PCLK1 = 50 MHz, standard mode 100 kHz: CCR = PCLK1 / (2 × 100 kHz) = 250 (§18.6.8),
/// so one SCL period is 2 × 250 / 50 MHz = 10 µs and a byte with its ACK 90 µs.
fn i2c_100khz() -> (I2c, Slave) {
    let slave = Slave::default();
    let mut bus = I2c::new(Box::new(slave.clone()));
    bus.set_clock(50_000_000);
    bus.write(i2c::CR2, 50, 0).unwrap();
    bus.write(i2c::CCR, 250, 0).unwrap();
    bus.write(i2c::TRISE, 51, 0).unwrap();
    bus.write(i2c::CR1, 1, 0).unwrap(); // PE
    (bus, slave)
}

fn sr1(bus: &mut I2c, t: Time) -> u32 {
    bus.read(i2c::SR1, t).unwrap()
}

#[test]
fn i2c_three_byte_read_follows_the_master_receiver_sequence() {
    let (mut bus, slave) = i2c_100khz();
    assert_eq!(bus.scl_period(), 10 * US);
    // START with ACK (§18.3.3, Figure 164: EV5 = SB).
    bus.write(i2c::CR1, 1 | (1 << 8) | (1 << 10), 0).unwrap();
    assert_eq!(
        sr1(&mut bus, 9 * US) & i2c::SR1_SB,
        0,
        "SB before one SCL period"
    );
    assert_ne!(
        sr1(&mut bus, 10 * US) & i2c::SR1_SB,
        0,
        "SB after one SCL period"
    );
    let sr2 = bus.read(i2c::SR2, 10 * US).unwrap();
    assert_eq!(
        sr2 & (i2c::SR2_MSL | i2c::SR2_BUSY),
        i2c::SR2_MSL | i2c::SR2_BUSY
    );
    // SB is cleared by reading SR1 then writing DR (the address).
    sr1(&mut bus, 11 * US);
    bus.write(i2c::DR, 0x81, 11 * US).unwrap();
    assert_eq!(sr1(&mut bus, 12 * US) & i2c::SR1_SB, 0);
    // EV6: ADDR after the 9 clocks of the address byte.
    assert_eq!(sr1(&mut bus, 100 * US) & i2c::SR1_ADDR, 0);
    assert_ne!(sr1(&mut bus, 101 * US) & i2c::SR1_ADDR, 0);
    // ADDR cleared by SR1 then SR2: reception starts; TRA clear (receiver).
    let sr2 = bus.read(i2c::SR2, 101 * US).unwrap();
    assert_eq!(sr2 & i2c::SR2_TRA, 0);
    assert_eq!(sr1(&mut bus, 101 * US) & i2c::SR1_ADDR, 0);
    // EV7: RXNE after each byte (9 SCL periods).
    assert_eq!(sr1(&mut bus, 190 * US) & i2c::SR1_RXNE, 0);
    assert_ne!(sr1(&mut bus, 191 * US) & i2c::SR1_RXNE, 0);
    assert_eq!(bus.read(i2c::DR, 191 * US).unwrap(), 0xA1);
    assert_ne!(sr1(&mut bus, 281 * US) & i2c::SR1_RXNE, 0);
    assert_eq!(bus.read(i2c::DR, 281 * US).unwrap(), 0xB2);
    // Before the last byte ends: ACK = 0 and STOP (EV7_1), as the HAL does.
    bus.write(i2c::CR1, 1 | (1 << 9), 282 * US).unwrap();
    assert_ne!(sr1(&mut bus, 371 * US) & i2c::SR1_RXNE, 0);
    assert_eq!(bus.read(i2c::DR, 371 * US).unwrap(), 0xC3);
    // The STOP follows the byte; CR1.STOP and SR2.BUSY/MSL clear when it is sent.
    assert_ne!(bus.read(i2c::CR1, 371 * US).unwrap() & (1 << 9), 0);
    assert_eq!(bus.read(i2c::CR1, 381 * US).unwrap() & (1 << 9), 0);
    assert_eq!(bus.read(i2c::SR2, 381 * US).unwrap() & 3, 0);
    let log = slave.0.borrow().log.clone();
    assert_eq!(
        log,
        ["S@10", "A40r@101", "ACK@191", "ACK@281", "NACK@371", "P@381"]
    );
}

#[test]
fn i2c_nacked_address_sets_af_which_a_zero_write_clears() {
    let (mut bus, slave) = i2c_100khz();
    bus.write(i2c::CR1, 1 | (1 << 8), 0).unwrap();
    sr1(&mut bus, 10 * US);
    bus.write(i2c::DR, 0x42 << 1, 10 * US).unwrap(); // address 0x42: nobody
    let s = sr1(&mut bus, 100 * US);
    assert_ne!(s & i2c::SR1_AF, 0);
    assert_eq!(s & i2c::SR1_ADDR, 0);
    // rc_w0: writing 1 leaves the flag, writing 0 clears it (§18.6.6).
    bus.write(i2c::SR1, 0xFFFF, 101 * US).unwrap();
    assert_ne!(sr1(&mut bus, 101 * US) & i2c::SR1_AF, 0);
    bus.write(i2c::SR1, 0, 101 * US).unwrap();
    assert_eq!(sr1(&mut bus, 101 * US) & i2c::SR1_AF, 0);
    assert_eq!(slave.0.borrow().log, ["S@10", "A42w@100"]);
}

#[test]
fn i2c_write_sets_txe_then_btf_per_byte() {
    let (mut bus, slave) = i2c_100khz();
    bus.write(i2c::CR1, 1 | (1 << 8), 0).unwrap();
    sr1(&mut bus, 10 * US);
    bus.write(i2c::DR, 0x80, 10 * US).unwrap();
    sr1(&mut bus, 100 * US);
    bus.read(i2c::SR2, 100 * US).unwrap();
    // EV8_1: TXE with the shift register empty.
    assert_ne!(sr1(&mut bus, 100 * US) & i2c::SR1_TXE, 0);
    bus.write(i2c::DR, 0x10, 100 * US).unwrap();
    let s = sr1(&mut bus, 101 * US);
    assert_ne!(s & i2c::SR1_TXE, 0, "DR moved into the shift register");
    assert_eq!(s & i2c::SR1_BTF, 0);
    assert_ne!(
        sr1(&mut bus, 190 * US) & i2c::SR1_BTF,
        0,
        "EV8_2: BTF after the byte"
    );
    bus.write(i2c::DR, 0x00, 190 * US).unwrap();
    assert_eq!(
        sr1(&mut bus, 191 * US) & i2c::SR1_BTF,
        0,
        "SR1 read + DR write clear BTF"
    );
    assert_ne!(sr1(&mut bus, 280 * US) & i2c::SR1_BTF, 0);
    bus.write(i2c::CR1, 1 | (1 << 9), 280 * US).unwrap();
    assert_eq!(bus.read(i2c::SR2, 290 * US).unwrap() & 3, 0);
    assert_eq!(
        slave.0.borrow().log,
        ["S@10", "A40w@100", "W10@190", "W00@280", "P@290"]
    );
}

/// USART1 at PCLK2 = 100 MHz with the image's BRR 0x364 (USARTDIV 54.25, §19.3.4: 115 207
/// baud): a frame of 10 bits takes 10 × 868 / 100 MHz = 86.8 µs.
fn usart_115200() -> Usart {
    let mut u = Usart::new();
    u.set_clock(100_000_000);
    u.write(usart::BRR, 0x364, 0, 0).unwrap();
    u.write(usart::CR1, (1 << 13) | (1 << 3) | (1 << 2), 0, 0)
        .unwrap(); // UE, TE, RE
    u
}

#[test]
fn usart_byte_time_and_tx_flags() {
    let mut u = usart_115200();
    assert_eq!(u.frame_ps(), 86_800_000);
    let sr = u.read(usart::SR, 0).unwrap();
    assert_eq!(
        sr & (usart::SR_TXE | usart::SR_TC),
        usart::SR_TXE | usart::SR_TC
    );
    u.write(usart::DR, b'A'.into(), 0, 0).unwrap();
    // The byte moved into the idle shift register: TXE set again, TC clear.
    let sr = u.read(usart::SR, 1).unwrap();
    assert_eq!(sr & (usart::SR_TXE | usart::SR_TC), usart::SR_TXE);
    u.write(usart::DR, b'B'.into(), 1, 0).unwrap();
    assert_eq!(u.read(usart::SR, 2).unwrap() & usart::SR_TXE, 0);
    assert_eq!(u.next_event(), Some(86_800_000));
    assert_ne!(u.read(usart::SR, 86_800_000).unwrap() & usart::SR_TXE, 0);
    assert_eq!(u.read(usart::SR, 173_599_999).unwrap() & usart::SR_TC, 0);
    assert_ne!(u.read(usart::SR, 173_600_000).unwrap() & usart::SR_TC, 0);
    let ends: Vec<(u8, Time)> = u.sent.iter().map(|s| (s.byte, s.end)).collect();
    assert_eq!(ends, [(b'A', 86_800_000), (b'B', 173_600_000)]);
    // TXEIE raises the interrupt while TXE is set.
    assert!(!u.irq());
    u.write(usart::CR1, (1 << 13) | (1 << 7) | 0xC, 173_600_000, 0)
        .unwrap();
    assert!(u.irq());
}

#[test]
fn usart_receive_overrun_and_clearing_sequences() {
    let mut u = usart_115200();
    u.receive_at(100 * US, b'x');
    u.receive_at(200 * US, b'y');
    assert_eq!(u.read(usart::SR, 99 * US).unwrap() & usart::SR_RXNE, 0);
    assert_ne!(u.read(usart::SR, 100 * US).unwrap() & usart::SR_RXNE, 0);
    // Not read before the next byte: ORE, and DR keeps the older byte (§19.3.3).
    let sr = u.read(usart::SR, 200 * US).unwrap();
    assert_ne!(sr & usart::SR_ORE, 0);
    assert_eq!(u.read(usart::DR, 200 * US).unwrap(), u32::from(b'x'));
    // SR then DR cleared RXNE and ORE.
    assert_eq!(
        u.read(usart::SR, 201 * US).unwrap() & (usart::SR_RXNE | usart::SR_ORE),
        0
    );
    assert_eq!(u.received.iter().filter(|r| r.lost).count(), 1);
    // RXNE is rc_w0.
    u.receive_at(300 * US, b'z');
    u.advance(300 * US);
    u.write(usart::SR, !usart::SR_RXNE, 300 * US, 0).unwrap();
    assert_eq!(u.read(usart::SR, 300 * US).unwrap() & usart::SR_RXNE, 0);
}

/// TIM5 as the image sets it: timer clock 100 MHz (APB1 at 50 MHz with prescaler 2, §6.2),
/// PSC 9999: one count per 100 µs.
#[test]
fn timer_counts_from_the_clock_with_preloaded_prescaler() {
    let mut t = Timer::new(true);
    t.set_clock(100_000_000, 0);
    t.write(timer::PSC, 9999, 0).unwrap();
    t.write(timer::ARR, 0xFFFF_FFFE, 0).unwrap();
    // PSC is preloaded: without an update event the counter still counts at /1.
    t.write(timer::CR1, 1, 0).unwrap();
    assert_eq!(
        t.read(timer::CNT, 1_000_000).unwrap(),
        100,
        "1 µs at 100 MHz, PSC 0"
    );
    // UG: counter cleared, PSC loaded, UIF set (URS = 0).
    t.write(timer::EGR, 1, 1_000_000).unwrap();
    assert_ne!(t.read(timer::SR, 1_000_000).unwrap() & 1, 0);
    assert_eq!(t.read(timer::CNT, 1_000_000).unwrap(), 0);
    assert_eq!(t.read(timer::CNT, 1_000_000 + 99_999_999).unwrap(), 0);
    assert_eq!(t.read(timer::CNT, 1_000_000 + 100 * US).unwrap(), 1);
    assert_eq!(t.read(timer::CNT, 1_000_000 + PS_PER_S).unwrap(), 10_000);
    assert_eq!(t.next_change(1_000_000), Some(1_000_000 + 100 * US + 1));
    // A 16-bit timer wraps from ARR to 0.
    let mut t3 = Timer::new(false);
    t3.set_clock(100_000_000, 0);
    t3.write(timer::ARR, 4999, 0).unwrap();
    t3.write(timer::CR1, 1, 0).unwrap();
    assert_eq!(
        t3.read(timer::CNT, 50 * US).unwrap(),
        0,
        "5000 counts: one period"
    );
}

#[test]
fn timer_pwm_mode_1_duty_is_ccr_over_period() {
    let mut t = Timer::new(false);
    t.write(timer::ARR, 4999, 0).unwrap();
    t.write(timer::CCMR1, 6 << 4, 0).unwrap(); // OC1M = 110, PWM mode 1
    t.write(timer::CCR1, 1250, 0).unwrap();
    assert_eq!(t.duty_ch1(), None, "counter stopped");
    t.write(timer::CR1, 1, 0).unwrap();
    assert_eq!(t.duty_ch1(), None, "CC1E clear");
    t.write(timer::CCER, 1, 0).unwrap();
    assert_eq!(t.duty_ch1(), Some(0.25));
    t.write(timer::CCR1, 6000, 0).unwrap();
    assert_eq!(
        t.duty_ch1(),
        Some(1.0),
        "CCR1 > ARR: always active (§13.3.10)"
    );
    t.write(timer::CCR1, 0, 0).unwrap();
    assert_eq!(t.duty_ch1(), Some(0.0));
}

fn unlocked_flash() -> Flash {
    let mut f = Flash::new();
    f.write(flash::KEYR, 0x4567_0123, 0).unwrap();
    f.write(flash::KEYR, 0xCDEF_89AB, 0).unwrap();
    assert_eq!(f.read(flash::CR, 0).unwrap() & flash::CR_LOCK, 0);
    f
}

#[test]
fn flash_unlock_needs_the_two_keys_in_order() {
    let mut f = Flash::new();
    assert_ne!(
        f.read(flash::CR, 0).unwrap() & flash::CR_LOCK,
        0,
        "locked at reset"
    );
    f.write(flash::KEYR, 0xCDEF_89AB, 0).unwrap();
    f.write(flash::KEYR, 0x4567_0123, 0).unwrap();
    f.write(flash::KEYR, 0xCDEF_89AB, 0).unwrap();
    // A wrong sequence locks FLASH_CR until reset (§3.5.1): the first write was wrong, and
    // every key after it is refused too.
    assert_ne!(f.read(flash::CR, 0).unwrap() & flash::CR_LOCK, 0);
    assert_eq!(f.errors.len(), 3);
    f.write(flash::CR, flash::CR_PG, 0).unwrap();
    assert_eq!(
        f.read(flash::CR, 0).unwrap() & flash::CR_PG,
        0,
        "locked CR ignores writes"
    );
    f.reset();
    f.write(flash::KEYR, 0x4567_0123, 0).unwrap();
    f.write(flash::KEYR, 0xCDEF_89AB, 0).unwrap();
    assert_eq!(f.read(flash::CR, 0).unwrap() & flash::CR_LOCK, 0);
}

#[test]
fn flash_program_only_clears_bits_and_checks_the_sequence() {
    let mut f = unlocked_flash();
    let off = 0x6_0000;
    // Without PG: PGSERR, nothing written.
    let e = f.program(off, 1, 0x00, 0);
    assert_eq!(e.changed, None);
    assert_ne!(f.read(flash::SR, 0).unwrap() & flash::SR_PGSERR, 0);
    f.write(flash::SR, flash::SR_PGSERR, 0).unwrap(); // rc_w1
    assert_eq!(f.read(flash::SR, 0).unwrap() & flash::SR_PGSERR, 0);
    // PG with PSIZE x8 (00) and a word access: PGPERR.
    f.write(flash::CR, flash::CR_PG, 0).unwrap();
    assert_eq!(f.program(off, 4, 0, 0).changed, None);
    assert_ne!(f.read(flash::SR, 0).unwrap() & flash::SR_PGPERR, 0);
    // Byte programs: 0xF0 then 0x0F leave 0x00 (1 → 0 only).
    let e = f.program(off, 1, 0xF0, 0);
    assert_eq!(e.changed, Some((off, 1)));
    assert_eq!(e.stall, flash::PROGRAM_PS);
    f.program(off, 1, 0x0F, 0);
    assert_eq!(f.mem[off as usize], 0x00);
    // BSY for the program time; EOP only with EOPIE (§3.8.4).
    assert_ne!(f.read(flash::SR, 0).unwrap() & flash::SR_BSY, 0);
    assert_eq!(
        f.read(flash::SR, 2 * flash::PROGRAM_PS).unwrap() & (flash::SR_BSY | flash::SR_EOP),
        0
    );
    f.write(flash::CR, flash::CR_PG | flash::CR_EOPIE, 0)
        .unwrap();
    f.program(off + 1, 1, 0x5A, 0);
    assert_ne!(f.read(flash::SR, 0).unwrap() & flash::SR_EOP, 0);
    // A halfword across a 128-bit row: PGAERR (PSIZE x16).
    f.write(flash::CR, flash::CR_PG | (1 << 8), 0).unwrap();
    assert_eq!(f.program(off + 15, 2, 0, 0).changed, None);
    assert_ne!(f.read(flash::SR, 0).unwrap() & flash::SR_PGAERR, 0);
}

#[test]
fn flash_sector_erase_sets_0xff_and_takes_the_datasheet_time() {
    let mut f = unlocked_flash();
    f.write(flash::CR, flash::CR_PG, 0).unwrap();
    f.program(0x6_0010, 1, 0x12, 0);
    // The last byte of sector 6.
    f.program(0x5_FFFF, 1, 0x34, 0);
    // SER, SNB = 7, STRT (§3.5.3), after the programs have finished.
    let e = f
        .write(flash::CR, flash::CR_SER | (7 << 3) | flash::CR_STRT, MS)
        .unwrap();
    assert_eq!(e.changed, Some((0x6_0000, 0x2_0000)));
    assert_eq!(e.stall, 2_000 * MS, "128 KB at x8: 2 s typical (DS10314)");
    assert_eq!(f.mem[0x6_0010], 0xFF);
    assert_eq!(f.mem[0x5_FFFF], 0x34, "sector 6 untouched");
    assert_ne!(f.read(flash::SR, 2_000 * MS).unwrap() & flash::SR_BSY, 0);
    assert_eq!(f.read(flash::SR, 2_001 * MS).unwrap() & flash::SR_BSY, 0);
    assert_eq!(f.read(flash::CR, 0).unwrap() & flash::CR_STRT, 0);
    // The flash-size word of the STM32F411CE (§24.2): 512 KB.
    assert_eq!(Flash::signature(flash::FLASH_SIZE_ADDR, 2), Ok(512));
}

#[test]
fn iwdg_times_out_after_rlr_prescaled_lsi_periods() {
    // PR = 3 (divider 32), RLR = 499: 499 × 32 / 32 kHz = 499 ms.
    let mut w = Iwdg::new();
    w.write(iwdg::KR, 0x5555, 0).unwrap();
    w.write(iwdg::PR, 3, 0).unwrap();
    w.write(iwdg::RLR, 499, 0).unwrap();
    assert_eq!(
        w.read(iwdg::SR, 0).unwrap(),
        3,
        "PVU and RVU while updating"
    );
    // Five LSI periods later the values are in effect (§15.4.4).
    let settled = 5 * PS_PER_S / iwdg::LSI_HZ;
    assert_eq!(w.read(iwdg::SR, settled).unwrap(), 0);
    w.write(iwdg::KR, 0xCCCC, settled).unwrap();
    assert_eq!(w.expiry(), Some(settled + 499 * MS));
    w.write(iwdg::KR, 0xAAAA, settled + 400 * MS).unwrap();
    assert_eq!(w.expiry(), Some(settled + 899 * MS));
    // Without the 0x5555 key PR/RLR are write-protected.
    w.write(iwdg::RLR, 10, settled + 400 * MS).unwrap();
    assert_eq!(w.read(iwdg::RLR, settled + 400 * MS).unwrap(), 499);
}

#[test]
fn iwdg_reload_right_after_a_new_rlr_uses_the_old_value() {
    let mut w = Iwdg::new();
    w.write(iwdg::KR, 0xCCCC, 0).unwrap(); // reset values: PR 0 (/4), RLR 0xFFF
    assert_eq!(w.expiry(), Some(4095 * 4 * PS_PER_S / iwdg::LSI_HZ));
    w.write(iwdg::KR, 0x5555, 0).unwrap();
    w.write(iwdg::RLR, 100, 0).unwrap();
    w.write(iwdg::KR, 0xAAAA, 1).unwrap();
    assert_eq!(
        w.expiry(),
        Some(1 + 4095 * 4 * PS_PER_S / iwdg::LSI_HZ),
        "RVU still set"
    );
    let later = MS;
    w.write(iwdg::KR, 0xAAAA, later).unwrap();
    assert_eq!(w.expiry(), Some(later + 100 * 4 * PS_PER_S / iwdg::LSI_HZ));
}

#[test]
fn rcc_pll_from_hse_gives_100_mhz_and_reset_flags_accumulate() {
    let mut r = Rcc::new();
    assert_eq!(r.clocks().sysclk, rcc::HSI_HZ);
    assert_eq!(
        r.reset_flags(),
        0x0E,
        "POR, PIN, BOR at power-on (reset value 0x0E00_0000)"
    );
    // HSE on: HSERDY follows (§6.3.1).
    let cr = r.read(rcc::CR).unwrap();
    r.write(rcc::CR, cr | (1 << 16)).unwrap();
    assert_ne!(r.read(rcc::CR).unwrap() & (1 << 17), 0);
    // PLLM 25, PLLN 200, PLLP /2, source HSE: 25 MHz / 25 × 200 / 2 = 100 MHz (§6.3.2).
    r.write(rcc::PLLCFGR, 25 | (200 << 6) | (1 << 22)).unwrap();
    let cr = r.read(rcc::CR).unwrap();
    r.write(rcc::CR, cr | (1 << 24)).unwrap();
    assert_ne!(r.read(rcc::CR).unwrap() & (1 << 25), 0, "PLLRDY");
    // APB1 /2, switch to the PLL: SWS follows SW (§6.3.3).
    r.write(rcc::CFGR, (4 << 10) | 2).unwrap();
    assert_eq!((r.read(rcc::CFGR).unwrap() >> 2) & 3, 2);
    let c = r.clocks();
    assert_eq!(
        (c.sysclk, c.hclk, c.pclk1, c.pclk2),
        (100_000_000, 100_000_000, 50_000_000, 100_000_000)
    );
    assert_eq!(
        c.tim1clk, 100_000_000,
        "APB1 prescaler 2: timers at 2 × PCLK1 (§6.2)"
    );
    // RMVF clears the flags; a watchdog reset sets IWDGRSTF and PINRSTF.
    r.write(rcc::CSR, 1 << 24).unwrap();
    assert_eq!(r.reset_flags(), 0);
    r.reset(ResetCause::Watchdog);
    assert_eq!(r.reset_flags(), 0x24);
    assert_eq!(r.clocks().sysclk, rcc::HSI_HZ, "clock tree back to HSI");
    r.reset(ResetCause::Software);
    assert_eq!(r.reset_flags(), 0x34, "flags accumulate until RMVF");
    // A brown-out is a power reset: the flags before it are cleared, BORRSTF and PINRSTF set.
    r.reset(ResetCause::BrownOut);
    assert_eq!(r.reset_flags(), 0x06);
}

#[test]
fn backup_registers_need_dbp_to_be_written_and_survive_resets_but_not_a_power_loss() {
    use stm32_harness::chip::Chip;
    use stm32_harness::periph::backup::{BKP0R, PWR, RTC};
    let mut chip = Chip::new(Box::new(Slave::default()));
    const APB1ENR: u32 = 0x4002_3840;
    let bkp0 = RTC + BKP0R;
    let bkp19 = RTC + BKP0R + 4 * 19;
    // Readable at once (0 after a backup-domain reset, §17.6.20); protected against writes
    // (§5.1.2).
    assert_eq!(chip.read(bkp0, 4, 0), 0);
    chip.write(bkp0, 4, 0x1234, 0);
    assert_eq!(chip.read(bkp0, 4, 0), 0, "written without DBP");
    // PWR_CR without the PWR clock (RCC_APB1ENR.PWREN, §6.3.11): the write goes nowhere.
    chip.write(PWR, 4, 1 << 8, 0);
    assert_eq!(
        chip.read(PWR, 4, 0) & (1 << 8),
        0,
        "PWR written with its clock off"
    );
    chip.write(APB1ENR, 4, 1 << 28, 0);
    let cr = chip.read(PWR, 4, 0);
    chip.write(PWR, 4, cr | (1 << 8), 0);
    chip.write(bkp0, 4, 0x1234, 0);
    chip.write(bkp19, 4, 0xABCD, 0);
    assert_eq!(chip.read(bkp0, 4, 0), 0x1234);
    assert_eq!(chip.backup.dropped, 2);
    // System and power resets keep the backup domain (§6.1.1, §6.1.2) and protect it again.
    for cause in [ResetCause::Watchdog, ResetCause::Pin, ResetCause::BrownOut] {
        chip.reset(cause, 0);
        assert_eq!(chip.read(bkp0, 4, 0), 0x1234, "{cause:?}");
        assert_eq!(chip.read(bkp19, 4, 0), 0xABCD, "{cause:?}");
        assert_eq!(chip.read(PWR, 4, 0) & (1 << 8), 0, "DBP after {cause:?}");
    }
    // A power-on with no battery on VBAT: a backup-domain reset (§6.1.3).
    chip.reset(ResetCause::PowerOn, 0);
    assert_eq!(chip.read(bkp0, 4, 0), 0);
}

#[test]
fn iwdg_new_prescaler_changes_the_rate_when_it_arrives() {
    // The image's erase: running at PR 3 (/32), RLR 499 (499 ms); it writes PR 6 (/256) and a
    // new RLR, then reloads at once: the reload takes the old RLR (RVU set), and once the new
    // prescaler arrives (5 LSI periods) the remaining counts go 8 times slower.
    let lsi = PS_PER_S / iwdg::LSI_HZ;
    let mut w = Iwdg::new();
    w.write(iwdg::KR, 0x5555, 0).unwrap();
    w.write(iwdg::PR, 3, 0).unwrap();
    w.write(iwdg::RLR, 499, 0).unwrap();
    w.write(iwdg::KR, 0xCCCC, 10 * lsi).unwrap();
    w.write(iwdg::KR, 0x5555, 10 * lsi).unwrap();
    w.write(iwdg::PR, 6, 10 * lsi).unwrap();
    w.write(iwdg::RLR, 999, 10 * lsi).unwrap();
    w.write(iwdg::KR, 0xAAAA, 10 * lsi).unwrap();
    assert_eq!(
        w.expiry(),
        Some(10 * lsi + 499 * 32 * lsi),
        "old RLR, old rate"
    );
    w.settle(15 * lsi);
    // 5 LSI periods at /32 used no whole count: 499 counts left, now at /256.
    assert_eq!(w.expiry(), Some(15 * lsi + 499 * 256 * lsi));
    // The next reload takes the new RLR.
    w.write(iwdg::KR, 0xAAAA, 20 * lsi).unwrap();
    assert_eq!(w.expiry(), Some(20 * lsi + 999 * 256 * lsi));
}
