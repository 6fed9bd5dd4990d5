//! Runs the ATmega2560 firmware in simavr against the simulated pump (see `scripts/simulate`).

use host_tests::simavr::firmware;
use host_tests::simavr::rig::{Rig, RigConfig};

fn main() {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let elf = firmware::ensure_elf().expect("firmware");
    let mut rig = Rig::new(RigConfig::new(elf)).expect("rig");
    let t0 = std::time::Instant::now();
    let end = rig.run_until(secs, |l| {
        println!("[{:9.4}] {}", l.cycle as f64 / 16e6, l.text);
        false
    });
    let wall = t0.elapsed().as_secs_f64();
    println!(
        "end={end:?} sim={:.3}s wall={wall:.2}s ratio={:.2}",
        rig.time_s(),
        rig.time_s() / wall
    );
    println!(
        "idle={:?} ticks={} duty changes={}",
        rig.idle_range(),
        rig.ticks().len(),
        rig.duty_log.len()
    );
    let s = rig.sensor.borrow();
    println!(
        "frames={} events={} errors={:?}",
        s.served().len(),
        s.events.len(),
        s.errors
    );
    for e in s.events.iter().take(12) {
        println!("{e:?}");
    }
}
