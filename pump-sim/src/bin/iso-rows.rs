//! What the ISO 80601-2-12 volume-control rows 1–8 ask of each blower: per row and inspiratory
//! shape, the peak airway pressure and flow and the largest steady-state duty the inspiration
//! needs, against the flow controller's largest duty (rows it cannot serve are named).
//!
//! ```text
//! cargo run --release -p pump-sim --bin iso-rows
//! ```
//!
//! The computations live in `pump_sim::iso`; this binary only prints.

use std::process::ExitCode;

use pump_sim::iso::ISO_ROWS;
use pump_sim::Blower;
use ridge_pump_firmware::selfid::DEFAULT_CONFIG;
use ridge_pump_firmware::setpoint::Shape;
use ridge_pump_firmware::units::FRACTION_PER_DUTY;

fn main() -> ExitCode {
    let max = f64::from(f32::from(DEFAULT_CONFIG.control.duty_max) * FRACTION_PER_DUTY);
    println!(
        "ISO 80601-2-12 Table 201.104 rows 1-8 (no bias flow; the ramp falls to 0): peak airway \
         pressure, peak flow, largest steady-state duty of the inspiration; the controller's \
         largest duty is {:.0} %\n",
        100.0 * max
    );
    println!("| row | C | R | rate | I:E | PEEP | VT | shape | peak pressure (cmH2O) | peak flow (slm) | duty: default | small | sluggish |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut short = Vec::new();
    for r in &ISO_ROWS {
        for shape in [Shape::Square, Shape::Ramp] {
            let needs: Vec<_> = Blower::ALL
                .iter()
                .map(|b| (b, r.needs(&b.params(), shape)))
                .collect();
            let n0 = needs[0].1;
            let cells: Vec<String> = needs
                .iter()
                .map(|(b, n)| match n.duty {
                    Some(d) if d <= max => format!("{:.1} %", 100.0 * d),
                    Some(d) => {
                        short.push(format!(
                            "row {} {shape:?} on the {} blower",
                            r.row,
                            b.name()
                        ));
                        format!("**{:.1} %**", 100.0 * d)
                    }
                    None => {
                        short.push(format!(
                            "row {} {shape:?} on the {} blower",
                            r.row,
                            b.name()
                        ));
                        "**> 100 %**".to_string()
                    }
                })
                .collect();
            println!(
                "| {} | {} | {} | {} | 1:{} | {} | {} | {:?} | {:.1} | {:.1} | {} |",
                r.row,
                r.compliance,
                r.resistance,
                r.rate,
                r.ie,
                r.peep,
                r.tidal,
                shape,
                n0.peak_pressure,
                n0.peak_flow,
                cells.join(" | ")
            );
        }
    }
    if short.is_empty() {
        println!("\nevery row within the controller's largest duty on every blower");
    } else {
        println!(
            "\nbeyond the controller's largest duty: {}",
            short.join("; ")
        );
    }
    ExitCode::SUCCESS
}
