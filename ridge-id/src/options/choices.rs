//! The two choices of how a run finds its model besides the estimator: [`Select`] (`--select`,
//! how the structure is chosen) and [`Refine`] (`--refine`, what is done to the chosen model),
//! each with its names on the command line and in reports.

/// `--refine`: the output-error refinement of the chosen model, or none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Refine {
    /// [`Refine::Oe`] when a validation record can judge it, else [`Refine::None`]
    /// ([`Options::refine_choice`](super::Options::refine_choice)). The default.
    #[default]
    Auto,
    /// The estimator's (ARX, equation-error) model as it is.
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
    /// [`Select::FreeRun`] when a validation record can judge the candidates, else
    /// [`Select::Criterion`] ([`Options::select_choice`](super::Options::select_choice)). The
    /// default.
    #[default]
    Auto,
    /// By the `--criterion` (the search).
    Criterion,
    /// Every candidate of the grid fitted by the estimator, the one with the lowest free-run
    /// RMSE on the validation record chosen among those whose input lags the estimation record
    /// excites, RMSEs within 1 % a tie that the criterion breaks
    /// ([`best_free_run`](crate::refine::best_free_run); needs `--validate`; the validation
    /// figures then no longer test the model on unseen data).
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
    Refine::Auto => "auto", "oe with --validate, unless --method, --criterion, --gamma or --structure asks for a particular model (not with --phase); else none";
    Refine::None => "none", "The estimator's ARX model as it is";
    Refine::Oe => "oe", "Output-error fit (Gauss-Newton on the free-run error) from it; with --validate kept only if it lowers the validation free-run RMSE";
);
names!(Select, "structure selection",
    Select::Auto => "auto", "free-run with --validate, unless --method, --criterion, --gamma or --structure asks for a particular model (not with --phase); else criterion";
    Select::Criterion => "criterion", "By --criterion (the search)";
    Select::FreeRun => "free-run", "Lowest free-run RMSE on the --validate record over the candidates the estimation record excites, within 1 % the criterion's pick";
);
