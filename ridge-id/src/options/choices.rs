//! The two choices of how a run finds its model besides the estimator: [`Select`] (`--select`,
//! how the structure is chosen) and [`Refine`] (`--refine`, what is done to the chosen model),
//! each with its names on the command line and in reports.

/// `--refine`: the output-error refinement of the chosen model, or none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Refine {
    /// The estimator's (ARX, equation-error) model as it is. The default.
    #[default]
    None,
    /// [`output_error`] from it; with a validation record kept only when it lowers the
    /// validation free-run RMSE.
    ///
    /// [`output_error`]: crate::refine::output_error
    Oe,
}

/// `--select`: how the structure is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Select {
    /// By the `--criterion` (the search). The default.
    #[default]
    Criterion,
    /// Every candidate of the grid fitted by the estimator, the one with the lowest free-run
    /// RMSE on the validation record chosen (needs `--validate`; the validation figures then
    /// no longer test the model on unseen data).
    FreeRun,
}

macro_rules! names {
    ($t:ty, $what:literal, $($v:path => $name:literal, $help:literal;)+) => {
        impl $t {
            /// All choices, in declaration order.
            pub const ALL: [$t; [$($name),+].len()] = [$($v),+];
            /// The name on the command line and in reports.
            pub const fn name(self) -> &'static str {
                match self { $($v => $name),+ }
            }
            /// `--help` text.
            pub const fn help(self) -> &'static str {
                match self { $($v => $help),+ }
            }
        }
        impl std::str::FromStr for $t {
            type Err = ridge_core_host::UnknownName;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                const NAMES: [&str; [$($name),+].len()] = [$($name),+];
                Self::ALL.into_iter().find(|v| v.name() == s).ok_or(
                    ridge_core_host::UnknownName { what: $what, expected: &NAMES },
                )
            }
        }
        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

names!(Refine, "refinement",
    Refine::None => "none", "The estimator's ARX model as it is";
    Refine::Oe => "oe", "Output-error fit (Gauss-Newton on the free-run error) from it; with --validate kept only if it lowers the validation free-run RMSE";
);
names!(Select, "structure selection",
    Select::Criterion => "criterion", "By --criterion (the search)";
    Select::FreeRun => "free-run", "Lowest free-run RMSE on the --validate record over all candidates";
);
