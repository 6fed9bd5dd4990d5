//! The plant as the command-line tools name it: a blower preset and an optional test lung,
//! one set of options shared by every simulator tool (`paper-tables`, `control-table`, the
//! simavr run).

use clap::{Args, ValueEnum};

use crate::{LungParams, PumpParams, Rig, Sfm3300Params};

/// A blower preset ([`PumpParams`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Blower {
    /// τ 0.15 s, 150 slm, 3 samples of delay (`PumpParams::default`).
    Default,
    /// τ 0.08 s up / 0.10 s down, 120 slm, 2 samples of delay (`PumpParams::small`).
    Small,
    /// τ 0.30 s up / 0.45 s down, 5 samples of delay (`PumpParams::sluggish`).
    Sluggish,
}

impl Blower {
    /// Every preset, in the order of the tables.
    pub const ALL: [Blower; 3] = [Blower::Default, Blower::Small, Blower::Sluggish];

    /// The preset's parameters.
    pub fn params(self) -> PumpParams {
        match self {
            Blower::Default => PumpParams::default(),
            Blower::Small => PumpParams::small(),
            Blower::Sluggish => PumpParams::sluggish(),
        }
    }

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Blower::Default => "default",
            Blower::Small => "small",
            Blower::Sluggish => "sluggish",
        }
    }
}

/// What the blower blows into.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Outlet {
    /// An open outlet: the flow is the blower's open-outlet flow.
    Open,
    /// C 50 mL/cmH₂O, R 5 cmH₂O/(L/s) (`LungParams::adult`).
    Adult,
    /// C 15 mL/cmH₂O, R 30 cmH₂O/(L/s) (`LungParams::stiff`).
    Stiff,
}

impl Outlet {
    /// Every preset, in the order of the tables.
    pub const ALL: [Outlet; 3] = [Outlet::Open, Outlet::Adult, Outlet::Stiff];

    /// The preset's lung, `None` for the open outlet.
    pub fn params(self) -> Option<LungParams> {
        match self {
            Outlet::Open => None,
            Outlet::Adult => Some(LungParams::adult()),
            Outlet::Stiff => Some(LungParams::stiff()),
        }
    }

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Outlet::Open => "open",
            Outlet::Adult => "adult",
            Outlet::Stiff => "stiff",
        }
    }
}

/// Plant options: `--plant`, `--lung` and overrides of the lung's parameters (an override
/// without `--lung` starts from the adult lung).
#[derive(Args, Clone, Debug, PartialEq)]
pub struct PlantArgs {
    /// Blower model.
    #[arg(long, value_enum, default_value = "default")]
    pub plant: Blower,
    /// Test lung behind the blower (`open`: none).
    #[arg(long, value_enum, default_value = "open")]
    pub lung: Outlet,
    /// Lung compliance C, mL/cmH₂O (ventilator checks: 10–50).
    #[arg(long, value_name = "ML_PER_CMH2O")]
    pub compliance: Option<f64>,
    /// Airway resistance R, cmH₂O/(L/s) (ventilator checks: 5–50).
    #[arg(long, value_name = "CMH2O_S_PER_L")]
    pub resistance: Option<f64>,
    /// PEEP held by the exhalation valve, cmH₂O.
    #[arg(long, value_name = "CMH2O")]
    pub peep: Option<f64>,
    /// Resistance of the open exhalation valve, cmH₂O/(L/s).
    #[arg(long, value_name = "CMH2O_S_PER_L")]
    pub valve_resistance: Option<f64>,
}

impl Default for PlantArgs {
    /// The default blower, open outlet.
    fn default() -> Self {
        Self::preset(Blower::Default, Outlet::Open)
    }
}

impl PlantArgs {
    /// A preset blower and outlet, no overrides.
    pub fn preset(plant: Blower, lung: Outlet) -> Self {
        Self {
            plant,
            lung,
            compliance: None,
            resistance: None,
            peep: None,
            valve_resistance: None,
        }
    }

    /// The blower's parameters.
    pub fn pump(&self) -> PumpParams {
        self.plant.params()
    }

    /// Whether the outlet feeds a valid lung (not the open outlet, no parameter out of range).
    pub fn has_lung(&self) -> bool {
        matches!(self.lung(), Ok(Some(_)))
    }

    /// The lung with the overrides applied, `None` for an open outlet; an error names a
    /// parameter out of range.
    pub fn lung(&self) -> Result<Option<LungParams>, String> {
        let overridden = self.compliance.is_some()
            || self.resistance.is_some()
            || self.peep.is_some()
            || self.valve_resistance.is_some();
        let base = match self.lung.params() {
            Some(l) => l,
            None if overridden => LungParams::adult(),
            None => return Ok(None),
        };
        let lung = LungParams {
            compliance: self.compliance.unwrap_or(base.compliance),
            resistance: self.resistance.unwrap_or(base.resistance),
            peep: self.peep.unwrap_or(base.peep),
            valve_resistance: self.valve_resistance.unwrap_or(base.valve_resistance),
            leak: base.leak,
        };
        lung.check()?;
        Ok(Some(lung))
    }

    /// A rig with this plant, sensor model `sensor` and noise seed `seed`.
    pub fn rig(&self, sensor: Sfm3300Params, seed: u64) -> Result<Rig, String> {
        let rig = Rig::new(self.pump(), sensor, seed);
        Ok(match self.lung()? {
            Some(l) => rig.with_lung(l),
            None => rig,
        })
    }

    /// One line for reports: `default blower, open outlet` or `sluggish blower, lung C 15
    /// mL/cmH2O R 30 cmH2O/(L/s) PEEP 3 cmH2O valve 10 cmH2O/(L/s)`.
    pub fn describe(&self) -> String {
        match self.lung() {
            Ok(None) => format!("{} blower, open outlet", self.plant.name()),
            Ok(Some(l)) => format!(
                "{} blower, lung C {} mL/cmH2O R {} cmH2O/(L/s) PEEP {} cmH2O valve {} cmH2O/(L/s)",
                self.plant.name(),
                l.compliance,
                l.resistance,
                l.peep,
                l.valve_resistance
            ),
            Err(e) => format!("{} blower, invalid lung ({e})", self.plant.name()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        plant: PlantArgs,
    }

    #[test]
    fn options_select_presets_and_override_the_lung() {
        let cli = Cli::parse_from(["t", "--plant", "sluggish", "--lung", "stiff", "--peep", "5"]);
        assert_eq!(cli.plant.pump(), PumpParams::sluggish());
        let lung = cli.plant.lung().unwrap().unwrap();
        assert_eq!(
            lung,
            LungParams {
                peep: 5.0,
                ..LungParams::stiff()
            }
        );
        // An override alone starts from the adult lung; the open outlet has none.
        let cli = Cli::parse_from(["t", "--compliance", "10"]);
        assert_eq!(cli.plant.lung().unwrap().unwrap().compliance, 10.0);
        assert_eq!(cli.plant.lung().unwrap().unwrap().resistance, 5.0);
        assert_eq!(Cli::parse_from(["t"]).plant.lung(), Ok(None));
        // Out of range is an error, not a lung.
        let cli = Cli::parse_from(["t", "--lung", "adult", "--resistance=-1"]);
        assert!(cli.plant.lung().is_err());
    }
}
