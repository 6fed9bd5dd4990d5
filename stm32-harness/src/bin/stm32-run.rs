use std::cell::RefCell;
use std::rc::Rc;
use stm32_harness::machine::Machine;
use stm32_harness::sensor::{SensorState, Sfm3300Slave};
fn main() {
    let elf = std::env::args().nth(1).unwrap();
    let secs: f64 = std::env::args().nth(2).map_or(3.0, |s| s.parse().unwrap());
    let st = Rc::new(RefCell::new(SensorState::new(pump_sim::Sfm3300::new(Default::default(), 1))));
    let mut m = Machine::new(std::path::Path::new(&elf), Box::new(Sfm3300Slave { state: st.clone() })).unwrap();
    let t0 = std::time::Instant::now();
    let step = 500_000_000u64;
    let end = (secs * 1e12) as u64;
    let mut t = step;
    while t <= end {
        if let Err(e) = m.run_until(t) { eprintln!("error {e}"); break; }
        st.borrow_mut().flow_slm = 10.0;
        if std::env::var("DBG").is_ok() { eprintln!("t {t} {}", m.debug_state()); }
        t += step;
    }
    let out: Vec<u8> = m.chip().usart1.sent.iter().map(|s| s.byte).collect();
    println!("{}", String::from_utf8_lossy(&out));
    println!("wall {:?} instr {} jumped {} ps faults {:?} resets {:?}", t0.elapsed(), m.instructions(), m.core().jumped, m.faults, m.resets);
}
