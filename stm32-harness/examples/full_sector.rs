//! A save into a full flash sector 7 (every slot used, so the image erases the sector first,
//! CPU stalled for the 2 s erase, with the watchdog raised to 8 s for it): does the chip
//! survive the erase? Prints the lines, the resets and the erases.
//!
//! `cargo run -p stm32-harness --example full_sector`

use stm32_harness::bench::{secs, Bench, BenchConfig};
use stm32_harness::firmware;
use stm32_harness::periph::flash;

fn main() -> Result<(), String> {
    let elf = firmware::ensure_elf()?;
    let mut mem = Bench::new(BenchConfig::new(&elf))?.flash();
    let (start, len) = flash::SECTORS[7];
    // Every slot used by a record that is not the image's (a zero header): no erased slot.
    mem[start as usize..(start + len) as usize].fill(0x00);
    let mut cfg = BenchConfig::new(&elf);
    cfg.flash = Some(mem);
    let mut b = Bench::new(cfg)?;
    b.run_until(75.0, |_| false)?;
    for l in b.lines.iter().filter(|l| !l.text.starts_with("TRACK")) {
        println!("[{:8.3} s] {}", secs(l.start), l.text);
    }
    let m = &b.machine;
    for r in &m.resets {
        println!("reset at {:.4} s: {:?}", secs(r.at), r.cause);
    }
    for (at, sector) in &m.chip().flash.erased {
        println!("erase of sector {sector} started at {:.4} s", secs(*at));
    }
    Ok(())
}
