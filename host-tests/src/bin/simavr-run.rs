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
    let mut end = host_tests::simavr::rig::RunEnd::Time;
    let mut t = 0.0;
    while t < secs {
        t += 1.0;
        let w = std::time::Instant::now();
        end = rig.run_until(t.min(secs), |l| {
            println!("[{:9.4}] {}", l.cycle as f64 / 16e6, l.text);
            false
        });
        eprintln!(
            "t={t} wall={:.2} pc={:#x} sp={:#x}",
            w.elapsed().as_secs_f64(),
            rig.machine.pc(),
            rig.machine.sp()
        );
    }
    let wall = t0.elapsed().as_secs_f64();
    println!(
        "end={end:?} sim={:.3}s wall={wall:.2}s ratio={:.2}",
        rig.time_s(),
        rig.time_s() / wall
    );
    println!(
        "idle={:?} ticks={} duty changes={}",
        rig.idle_pcs(),
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
