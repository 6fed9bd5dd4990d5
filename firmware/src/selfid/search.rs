//! The structure search on the estimation record: run blocking by the state machine
//! ([`SelfIdentification::search`]), or taken out as a [`SearchJob`] that the board runs while
//! the ticks go on ([`SelfIdentification::take_search`] → [`SearchJob::run`] →
//! [`SelfIdentification::finish_search`]).

use ridge_core::{ArxModel, InputMap, IntGram, Normal, Search};

use crate::event::{Event, RejectReason, SearchStats};

use super::recording::{absolute_model, Recording};
use super::{Phase, SelfIdentification, Settings};
use crate::units::MODEL_SCALE;

/// A structure search taken out of the state machine ([`SelfIdentification::take_search`]),
/// to run in the main loop while the timer interrupt keeps calling
/// [`SelfIdentification::tick`].
#[derive(Debug, Clone)]
pub struct SearchJob {
    rec: Recording,
    search: Search<f32>,
    min_response: f32,
    generation: u8,
}

/// The result of a [`SearchJob`], for [`SelfIdentification::finish_search`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchOutcome {
    result: Result<(ArxModel<f32>, SearchStats), RejectReason>,
    /// The record's static map (the model's input goes through it).
    map: InputMap,
    generation: u8,
}

impl SearchOutcome {
    /// The identified model and the search figures, or why the record was refused.
    pub fn result(&self) -> Result<(ArxModel<f32>, SearchStats), RejectReason> {
        self.result
    }
}

impl SearchJob {
    /// Samples in the estimation record.
    pub fn samples(&self) -> u32 {
        self.rec.gram.len()
    }

    /// The exact statistics of the estimation record.
    pub fn gram(&self) -> &IntGram {
        &self.rec.gram
    }

    /// Runs the search: the excitation check, `Gram::normal::<f32>`, then the pruned
    /// structure search ([`ridge_core::Search::run_with_progress`], identical to `Search::run`). Calls `pet` at
    /// least once per Cholesky factorisation or Ridge-M iterate (see [`ridge_core::Search::run_with_progress`]).
    pub fn run(&self, mut pet: impl FnMut()) -> SearchOutcome {
        SearchOutcome {
            result: evaluate(&self.rec, &self.search, self.min_response, &mut pet),
            map: self.rec.map,
            generation: self.generation,
        }
    }
}

/// The excitation check, `Gram::normal::<f32>`, the pruned search and the conversion to the
/// absolute model, petting the watchdog before, between and after.
fn evaluate(
    rec: &Recording,
    search: &Search<f32>,
    min_response: f32,
    pet: &mut impl FnMut(),
) -> Result<(ArxModel<f32>, SearchStats), RejectReason> {
    pet();
    // Filled in place: `Gram::normal` would return the 848-byte statistics by value.
    let mut normal = Normal::<f32>::empty();
    normal_equations(rec, min_response, &mut normal)?;
    pet();
    select(&normal, rec.v0, rec.y0, search, pet)
}

/// The excitation check (response RMS at least `min_response`) and the normal equations of
/// `rec` into `normal`, or why the record is refused.
fn normal_equations(
    rec: &Recording,
    min_response: f32,
    normal: &mut Normal<f32>,
) -> Result<(), RejectReason> {
    let rms = rec.response_rms();
    if rms < min_response || rms.is_nan() {
        return Err(RejectReason::NotExcited { rms });
    }
    rec.gram
        .normal_into(&MODEL_SCALE, normal)
        .map_err(|e| match e {
            ridge_core::Error::NotExcited => RejectReason::NotExcited { rms },
            e => RejectReason::Search(e),
        })
}

/// The pruned search on `normal` (deviations from the operating point `v0`, `y0`, counts) and
/// the conversion to the absolute model, petting the watchdog as it goes and after.
fn select(
    normal: &Normal<f32>,
    v0: i16,
    y0: i16,
    search: &Search<f32>,
    pet: &mut impl FnMut(),
) -> Result<(ArxModel<f32>, SearchStats), RejectReason> {
    let found = search
        .run_with_progress(normal, None, pet)
        .map_err(RejectReason::Search)?;
    pet();
    let model = absolute_model(&found.fit.model(), v0, y0).map_err(RejectReason::Search)?;
    Ok((
        model,
        SearchStats {
            score: found.score,
            candidates: found.candidates,
            evaluated: found.evaluated,
            skipped: found.skipped,
            iterations: found.fit.iterations,
            samples: normal.samples(),
        },
    ))
}

impl<S: Settings> SelfIdentification<S> {
    /// `true` while the structure search is due: the board should call
    /// [`search`](Self::search) (or [`take_search`](Self::take_search)) from its main loop.
    pub fn needs_search(&self) -> bool {
        matches!(self.phase, Phase::SearchReady { .. })
    }

    /// Runs the structure search now (blocking; seconds on the ATmega2560), calling `pet`
    /// often enough for a watchdog of ≥ 250 ms (at least once per ≤ 13 × 13 Cholesky
    /// factorisation or Ridge-M iterate). Returns the event to report: [`Event::Identified`]
    /// (validation follows) or [`Event::Rejected`]. `None` when no search was due.
    ///
    /// No tick can run meanwhile: the pump keeps the base duty and faults are not detected
    /// until the search returns. Use [`take_search`](Self::take_search) to keep ticking.
    ///
    /// The same as [`prepare_search`](Self::prepare_search) followed by
    /// [`run_search`](Self::run_search), which a board with little RAM calls from two stack
    /// frames of its own.
    pub fn search(&mut self, mut pet: impl FnMut()) -> Option<Event> {
        pet();
        self.prepare_search();
        self.run_search(pet)
    }

    /// First half of the blocking [`search`](Self::search): the excitation check and the
    /// normal equations, built from the estimation record in its place in the state machine
    /// (848 B on the ATmega2560 that are then not on the search's stack). Then
    /// [`run_search`](Self::run_search) is due, which also reports a refused record. Does
    /// nothing when no search is due. Never inlined: the record is copied into this frame,
    /// which must be gone before the search's frame is built.
    #[inline(never)]
    pub fn prepare_search(&mut self) {
        if !matches!(self.phase, Phase::SearchReady { .. }) {
            return;
        }
        let Phase::SearchReady { rec } = core::mem::replace(&mut self.phase, Phase::Searching)
        else {
            return;
        };
        self.phase = Phase::SearchNormal {
            normal: Normal::empty(),
            map: rec.map,
            v0: rec.v0,
            y0: rec.y0,
        };
        if let Phase::SearchNormal { normal, .. } = &mut self.phase {
            let min_response = self.settings.config().min_response;
            if let Err(reason) = normal_equations(&rec, min_response, normal) {
                self.phase = Phase::SearchRefused(reason, rec.map);
            }
        }
    }

    /// Second half of the blocking [`search`](Self::search), after
    /// [`prepare_search`](Self::prepare_search): the pruned structure search on the prepared
    /// normal equations and the conversion to the absolute model, calling `pet` as
    /// [`search`](Self::search) does. Returns [`search`](Self::search)'s event; `None` when
    /// nothing was prepared.
    pub fn run_search(&mut self, mut pet: impl FnMut()) -> Option<Event> {
        let (result, map) = match &self.phase {
            Phase::SearchNormal {
                normal,
                map,
                v0,
                y0,
            } => {
                pet();
                let search = &self.settings.config().search;
                (select(normal, *v0, *y0, search, &mut pet), *map)
            }
            Phase::SearchRefused(reason, map) => (Err(*reason), *map),
            _ => return None,
        };
        self.phase = Phase::Searching;
        self.finish_search(SearchOutcome {
            result,
            map,
            generation: self.generation,
        })
    }

    /// Takes the due structure search out of the state machine (`None` when none is due).
    /// Ticks go on at the base duty, with fault detection, until
    /// [`finish_search`](Self::finish_search).
    pub fn take_search(&mut self) -> Option<SearchJob> {
        if !self.needs_search() {
            return None;
        }
        match core::mem::replace(&mut self.phase, Phase::Searching) {
            Phase::SearchReady { rec } => Some(SearchJob {
                rec,
                search: self.settings.config().search,
                min_response: self.settings.config().min_response,
                generation: self.generation,
            }),
            other => {
                self.phase = other;
                None
            }
        }
    }

    /// Applies the result of a [`SearchJob`]: starts the validation or handles the
    /// rejection. Returns the event to report ([`Event::Identified`] or [`Event::Rejected`]),
    /// or `None` when the outcome is stale (a fault or a re-identification came in between).
    pub fn finish_search(&mut self, outcome: SearchOutcome) -> Option<Event> {
        if !matches!(self.phase, Phase::Searching) || outcome.generation != self.generation {
            return None;
        }
        match outcome.result {
            Ok((model, stats)) => match self.validation(model, outcome.map) {
                Some(phase) => {
                    self.phase = phase;
                    Some(Event::Identified { model, stats })
                }
                // Not reached: the same map gave the estimation record its levels.
                None => Some(self.reject(RejectReason::NotExcited { rms: 0.0 })),
            },
            Err(reason) => Some(self.reject(reason)),
        }
    }
}
