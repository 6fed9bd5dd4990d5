//! `--initial measured|zero`: what the estimation assumes before the record starts.

use ridge_core_host::{Grid, UnknownName};

/// The initial conditions of the regression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Initial {
    /// The first `M` samples (`M` = the grid's longest lag, the same for every candidate,
    /// [`Grid::longest_lag`]) fill the lag history and contribute no row: every row of the
    /// regression holds measured samples only, as MATLAB `arx` and SysIdentPy fit
    /// ([`ridge_core_host::MeasuredGram`]). The default.
    #[default]
    Measured,
    /// Zero history before the record: every sample is a row, its missing lags are zero
    /// (eq. 6 of the paper, what the device does).
    Zero,
}

impl Initial {
    /// Both choices, in declaration order.
    pub const ALL: [Initial; 2] = [Initial::Measured, Initial::Zero];

    /// The name on the command line, in reports and in JSON: `measured`, `zero`.
    pub const fn name(self) -> &'static str {
        match self {
            Initial::Measured => "measured",
            Initial::Zero => "zero",
        }
    }

    /// `--help` text.
    pub const fn help(self) -> &'static str {
        match self {
            Initial::Measured => {
                "The first M samples (the grid's longest lag) fill the lag history, no row of zeros"
            }
            Initial::Zero => "Zero history before the record (the paper's eq. 6, the device's)",
        }
    }

    /// Samples that only fill the lag history on a search over `grid`: its longest lag
    /// for [`Initial::Measured`], 0 for [`Initial::Zero`].
    pub fn samples(self, grid: &Grid) -> u32 {
        match self {
            Initial::Measured => grid.longest_lag() as u32,
            Initial::Zero => 0,
        }
    }
}

impl std::fmt::Display for Initial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Initial {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, UnknownName> {
        const NAMES: [&str; 2] = [Initial::Measured.name(), Initial::Zero.name()];
        Initial::ALL
            .into_iter()
            .find(|i| i.name() == s)
            .ok_or(UnknownName {
                what: "initial conditions",
                expected: &NAMES,
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ridge_core_host::OrderRange;

    #[test]
    fn names_round_trip_and_samples_are_the_longest_lag() {
        for i in Initial::ALL {
            assert_eq!(i.name().parse::<Initial>(), Ok(i));
        }
        assert!("measure".parse::<Initial>().is_err());
        let g = Grid::PAPER;
        assert_eq!(Initial::Measured.samples(&g), 11); // d 6 + q 6 − 1
        assert_eq!(Initial::Zero.samples(&g), 0);
        let g = Grid {
            p: OrderRange::new(1, 9),
            q: OrderRange::new(2, 3),
            d: OrderRange::new(0, 2),
        };
        assert_eq!(Initial::Measured.samples(&g), 9); // p
    }
}
