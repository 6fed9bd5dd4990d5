//! The report lines' parser (`lines`) against their writer (`event`): every event kind
//! formatted by the firmware's own code and parsed back equal to the values it was made of.
//!
//! The values are chosen on the printed grid and exact in `f32` (dyadic fractions with no more
//! decimals than the line prints: 0.9375 with 6 decimals, 87.5 with 1), so the parsed numbers
//! equal the event's exactly; one test takes values off the grid and checks each within half a
//! unit of the last printed digit. The expected keys, words and numbers are written here from
//! each event's documented line (`event` module docs), not taken from the writer.

use ridge_core::control::{DesignError, ModelFault};
use ridge_core::{ArxModel, Error as CoreError, InputMap, MapError, Offset, MAP_KNOTS};
use ridge_pump_firmware::event::{
    core_error_name, map_error_name, BreathSummary, ControlRefusal, Event, FaultReason, ReidReport,
    ReidVerdict, RejectReason, Residuals, SearchStats, SensorFault, StoredReason, LINE_MAX,
    RECORD_NAME,
};
use ridge_pump_firmware::lines::{
    number, BreathLine, ExciteLine, IdLine, LineError, LoadedLine, MapLine, ParsedLine,
    PrintedModel, ReidLine, ScanLine, ValidateLine, VolumeAlarmLine,
};
use ridge_pump_firmware::persist::PersistError;

/// A blower-like map on the firmware's grid (15 % + k · 5.33 %), knots in counts.
fn map() -> InputMap {
    let mut knots = [0i16; MAP_KNOTS];
    for (k, v) in knots.iter_mut().enumerate() {
        *v = (759 + 90 * k * k + k) as i16;
    }
    InputMap::new(1_500, 533, knots).unwrap()
}

fn text(e: &Event) -> String {
    let l = e.line::<LINE_MAX>();
    assert!(!l.is_truncated(), "{}", l.as_str());
    l.as_str().to_owned()
}

/// A field's expected value.
#[derive(Clone, Debug, PartialEq)]
enum V {
    /// A number.
    N(f64),
    /// A word (`sensor=crc`).
    W(&'static str),
    /// `a/b` of whole numbers.
    R(i64, i64),
    /// `a<b` of numbers (a value below its limit).
    Lt(f64, f64),
    /// `a/b` of numbers (NaN compared as NaN).
    P(f64, f64),
    /// A comma-separated list.
    L(Vec<f64>),
}

/// What a line must hold: keyword, bare words, fields.
struct Expected {
    keyword: &'static str,
    words: Vec<&'static str>,
    fields: Vec<(&'static str, V)>,
}

fn exp(keyword: &'static str, words: &[&'static str], fields: Vec<(&'static str, V)>) -> Expected {
    Expected {
        keyword,
        words: words.to_vec(),
        fields,
    }
}

/// Checks the parsed line against `want`: the same keyword, words, and keys, each value equal.
fn check(line: &str, want: &Expected) {
    let p = ParsedLine::parse(line);
    assert_eq!(p.keyword, want.keyword, "{line}");
    assert_eq!(p.words, want.words, "{line}");
    let keys: Vec<&str> = p.fields.keys().map(String::as_str).collect();
    let mut want_keys: Vec<&str> = want.fields.iter().map(|(k, _)| *k).collect();
    want_keys.sort_unstable();
    assert_eq!(keys, want_keys, "{line}");
    for (k, v) in &want.fields {
        let raw = p.get(k).unwrap();
        let got = match v {
            V::N(_) => V::N(p.num(k).unwrap_or_else(|| panic!("{k} in {line}"))),
            V::W(w) => {
                assert_eq!(raw, *w, "{k} in {line}");
                v.clone()
            }
            V::R(..) => {
                let (a, b) = p.ratio(k).unwrap_or_else(|| panic!("{k} in {line}"));
                V::R(a, b)
            }
            V::Lt(..) => {
                let (a, b) = raw
                    .split_once('<')
                    .unwrap_or_else(|| panic!("{k} in {line}"));
                V::Lt(number(a).unwrap(), number(b).unwrap())
            }
            V::L(_) => V::L(p.list(k).unwrap_or_else(|| panic!("{k} in {line}"))),
            V::P(..) => {
                let (a, b) = raw
                    .split_once('/')
                    .unwrap_or_else(|| panic!("{k} in {line}"));
                V::P(number(a).unwrap(), number(b).unwrap())
            }
        };
        // NaN prints `nan` and parses back as NaN: compared by the bits' meaning.
        let same = match (&got, v) {
            (V::N(a), V::N(b)) => a == b || (a.is_nan() && b.is_nan()),
            (V::P(a, b), V::P(c, d)) => {
                (a == c || (a.is_nan() && c.is_nan())) && (b == d || (b.is_nan() && d.is_nan()))
            }
            _ => &got == v,
        };
        assert!(same, "{k} in {line}: {got:?} != {v:?}");
    }
}

fn f(x: f32) -> V {
    V::N(f64::from(x))
}

fn int(x: impl Into<i64>) -> V {
    V::N(x.into() as f64)
}

/// Flow counts (1/120 slm) as the line's slm: 3 decimals of `counts / 120`, rounded half away
/// from zero (the counts below are chosen so that this is exact: multiples of 3 counts are
/// multiples of 0.025 slm).
fn slm(counts: i16) -> V {
    assert_eq!(counts % 3, 0, "choose counts on the 0.025 slm grid");
    V::N(f64::from(counts) / 120.0)
}

/// Duty (1/10 000) in percent.
fn percent(duty: u16) -> V {
    V::N(f64::from(duty) / 100.0)
}

fn list(v: &[f32]) -> V {
    V::L(v.iter().map(|&x| f64::from(x)).collect())
}

/// A model with θ, φ and c exact at 6 decimals.
fn model() -> ArxModel<f32> {
    ArxModel::new(
        &[0.9375, -0.125],
        &[6.5, -1.25, 0.0625],
        3,
        Offset::Intercept,
        -19.0625,
    )
    .unwrap()
}

fn model_fields(m: &ArxModel<f32>) -> Vec<(&'static str, V)> {
    let s = m.structure();
    let off = i64::from(m.offset() == Offset::Intercept);
    vec![
        ("p", int(s.p)),
        ("q", int(s.q)),
        ("d", int(s.d)),
        ("off", int(off)),
        ("theta", list(m.theta())),
        ("phi", list(m.phi())),
        ("c", f(m.intercept())),
    ]
}

fn printed(m: &ArxModel<f32>) -> PrintedModel {
    let s = m.structure();
    PrintedModel {
        p: s.p,
        q: s.q,
        d: s.d,
        offset: m.offset(),
        theta: m.theta().iter().map(|&v| f64::from(v)).collect(),
        phi: m.phi().iter().map(|&v| f64::from(v)).collect(),
        c: f64::from(m.intercept()),
    }
}

fn model_fault(m: ModelFault<f32>) -> (Vec<&'static str>, Vec<(&'static str, V)>) {
    match m {
        ModelFault::NonFinite => (vec!["nonfinite"], vec![]),
        ModelFault::Unstable => (vec!["unstable"], vec![]),
        ModelFault::Gain { gain } => (vec![], vec![("gain", f(gain))]),
    }
}

fn fault(r: FaultReason) -> (Vec<&'static str>, Vec<(&'static str, V)>) {
    match r {
        FaultReason::Sensor { error, count } => (
            vec![],
            vec![("sensor", V::W(error.name())), ("n", int(count))],
        ),
        FaultReason::FlowRange { counts } => (vec!["range"], vec![("flow", slm(counts))]),
        FaultReason::Stall { duty, counts } => (
            vec!["stall"],
            vec![("duty", percent(duty)), ("flow", slm(counts))],
        ),
        FaultReason::Frozen { counts } => (
            vec![],
            vec![("sensor", V::W("frozen")), ("flow", slm(counts))],
        ),
        FaultReason::NoFlow {
            duty,
            counts,
            expected,
        } => (
            vec!["noflow"],
            vec![
                ("duty", percent(duty)),
                ("flow", slm(counts)),
                ("expect", slm(expected)),
            ],
        ),
        FaultReason::ResetLoop { watchdog, brownout } => (
            vec!["resets"],
            vec![("watchdog", int(watchdog)), ("brownout", int(brownout))],
        ),
        FaultReason::Unidentified { attempts } => {
            (vec!["unidentified"], vec![("attempts", int(attempts))])
        }
        FaultReason::Control(ControlRefusal::Model(m)) => {
            let (mut words, fields) = model_fault(m);
            words.insert(0, "control");
            (words, fields)
        }
        FaultReason::Control(ControlRefusal::Design { error, tries }) => {
            let mut words = vec!["control"];
            let mut fields = vec![("tries", int(tries))];
            match error {
                DesignError::Spec => words.push("spec"),
                DesignError::Singular => words.push("singular"),
                DesignError::SlowPoles => words.push("slow-poles"),
                DesignError::Poles => words.push("poles"),
                DesignError::Margin { margin } => fields.push(("margin", f(margin))),
            }
            (words, fields)
        }
    }
}

fn residual_fields(r: &Residuals) -> Vec<(&'static str, V)> {
    let n = f64::from(r.samples);
    vec![
        ("rms", V::N((f64::from(r.sum_sq) / n).sqrt())),
        ("mean", V::N(f64::from(r.sum) / n)),
        ("flow", V::N(f64::from(r.sum_flow) / n)),
    ]
}

/// What `e`'s line holds, from `e`'s values (the exhaustive match makes a new event kind
/// fail to compile here until it is covered).
fn expected(e: &Event) -> Expected {
    match *e {
        Event::StoredRejected(r) => {
            let (words, fields) = match r {
                StoredReason::Record(p) => (vec![p.name()], vec![]),
                StoredReason::Model(m) => model_fault(m),
                StoredReason::MapSlope { slope } => (vec![], vec![("map-slope", f(slope))]),
                StoredReason::Fit { fit, min } => {
                    (vec![], vec![("fit", V::Lt(f64::from(fit), f64::from(min)))])
                }
            };
            exp("STORED-REJECTED", &words, fields)
        }
        Event::Loaded { model, fit } => {
            let mut fields = model_fields(&model);
            fields.push(("fit", f(fit)));
            exp("LOADED", &[], fields)
        }
        Event::Scan {
            samples,
            lag,
            u0,
            y0,
            attempt,
            attempts,
        } => exp(
            "SCAN",
            &[],
            vec![
                ("n", int(samples)),
                ("lag", int(lag)),
                ("u0", percent(u0)),
                ("y0", slm(y0)),
                ("attempt", V::R(attempt.into(), attempts.into())),
            ],
        ),
        Event::Map(map) => exp(
            "MAP",
            &[],
            vec![
                ("first", percent(map.first())),
                ("step", percent(map.step())),
                // Each knot's counts in slm to 3 decimals, rounded half away from zero.
                (
                    "flow",
                    V::L(
                        map.knots()
                            .iter()
                            .map(|&k| (f64::from(k) * 1000.0 / 120.0).round() / 1000.0)
                            .collect(),
                    ),
                ),
            ],
        ),
        Event::Excite {
            samples,
            u0,
            y0,
            attempt,
            attempts,
        } => exp(
            "EXCITE",
            &["flow-steps"],
            vec![
                ("n", int(samples)),
                ("u0", percent(u0)),
                ("y0", slm(y0)),
                ("attempt", V::R(attempt.into(), attempts.into())),
            ],
        ),
        Event::Identified { model, stats } => {
            let mut fields = model_fields(&model);
            fields.extend([
                ("score", f(stats.score)),
                (
                    "eval",
                    V::R(stats.evaluated.into(), stats.candidates.into()),
                ),
                ("skip", int(stats.skipped)),
                ("iters", int(stats.iterations)),
            ]);
            exp("ID", &[], fields)
        }
        Event::Validate { samples } => exp("VALIDATE", &["flow-steps"], vec![("n", int(samples))]),
        Event::Accepted {
            fit,
            rmse,
            one_step,
            samples,
        } => exp(
            "ACCEPT",
            &["persist"],
            vec![
                ("fit", f(fit)),
                ("rmse", f(rmse)),
                ("one", f(one_step)),
                ("n", int(samples)),
            ],
        ),
        Event::Rejected {
            reason,
            attempt,
            attempts,
        } => {
            let (words, mut fields) = match reason {
                RejectReason::NotExcited { rms } => (vec!["not-excited"], vec![("rms", f(rms))]),
                RejectReason::Map(e) => (vec![], vec![("map", V::W(map_error_name(e)))]),
                RejectReason::Search(e) => (vec![], vec![("search", V::W(core_error_name(e)))]),
                RejectReason::Fit { fit, min } => {
                    (vec![], vec![("fit", V::Lt(f64::from(fit), f64::from(min)))])
                }
                RejectReason::NonFinite => (vec!["nonfinite"], vec![]),
                RejectReason::SensorGaps { gaps } => (vec![], vec![("gaps", int(gaps))]),
            };
            fields.push(("attempt", V::R(attempt.into(), attempts.into())));
            exp("REJECT", &words, fields)
        }
        Event::Control {
            tau,
            alpha,
            beta,
            gamma,
            kept,
            margin,
            tries,
            preview,
        } => exp(
            "CTRL",
            &[],
            vec![
                ("method", V::W("pole-placement")),
                ("tau", f(tau)),
                ("poles", list(&[alpha, beta])),
                ("ref", f(gamma)),
                ("kept", int(kept)),
                ("mm", f(margin)),
                ("tries", int(tries)),
                ("preview", int(preview)),
            ],
        ),
        Event::Track {
            sum_setpoint,
            sum_flow,
            sum_sq,
            max,
            sum_duty,
            samples,
            tick,
        } => {
            let n = f64::from(samples);
            exp(
                "TRACK",
                &[],
                vec![
                    ("sp", V::N(f64::from(sum_setpoint) / n)),
                    ("flow", V::N(f64::from(sum_flow) / n)),
                    ("rms", V::N((f64::from(sum_sq) / n).sqrt())),
                    ("max", f(max)),
                    ("duty", V::N(f64::from(sum_duty) / n / 100.0)),
                    ("tick", int(tick)),
                ],
            )
        }
        Event::Alarm { on: false, .. } => exp("ALARM", &["track", "clear"], vec![]),
        Event::Alarm {
            on: true,
            error,
            ticks,
        } => exp(
            "ALARM",
            &["track"],
            vec![("err", f(error)), ("s", V::N(f64::from(ticks) / 100.0))],
        ),
        Event::Residual(r) => {
            let mut fields = residual_fields(&r);
            fields.push(("n", int(r.samples)));
            exp("RES", &[], fields)
        }
        Event::Drift {
            residuals,
            seconds,
            reidentify,
        } => {
            let mut fields = residual_fields(&residuals);
            fields.extend([("s", int(seconds)), ("reid", int(u8::from(reidentify)))]);
            exp("DRIFT", &[], fields)
        }
        Event::Breath(b) => exp(
            "BREATH",
            &[],
            vec![
                ("n", int(b.number)),
                ("vt", f(b.tidal)),
                ("peep", f(b.peep)),
                ("vd", f(b.delivered)),
                ("cmd", f(b.command)),
                ("peak", slm(b.peak)),
                (
                    "rms",
                    V::N((f64::from(b.sum_sq) / f64::from(b.samples)).sqrt()),
                ),
            ],
        ),
        Event::VolumeAlarm { on: false, .. } => exp("ALARM", &["volume", "clear"], vec![]),
        Event::VolumeAlarm {
            on: true,
            delivered,
            tidal,
        } => exp(
            "ALARM",
            &["volume"],
            vec![("vd", f(delivered)), ("vt", f(tidal))],
        ),
        Event::Reid(r) => {
            let mut fields = vec![
                ("breath", int(r.breath)),
                (
                    "verdict",
                    V::W(match r.verdict {
                        ReidVerdict::Accepted => "accepted",
                        ReidVerdict::Kept => "kept",
                        ReidVerdict::NotExcited => "not-excited",
                        ReidVerdict::Model => "model",
                        ReidVerdict::Fit => "fit",
                        ReidVerdict::Numeric => "numeric",
                        ReidVerdict::Design(_) => "design",
                    }),
                ),
                ("gain", f(r.gain)),
                ("fit", V::P(f64::from(r.fit), f64::from(r.running))),
                ("v-rms", f(r.v_rms)),
            ];
            if let ReidVerdict::Design(why) = r.verdict {
                match why {
                    ControlRefusal::Model(ModelFault::NonFinite) => {
                        fields.push(("why", V::W("nonfinite")))
                    }
                    ControlRefusal::Model(ModelFault::Unstable) => {
                        fields.push(("why", V::W("unstable")))
                    }
                    ControlRefusal::Model(ModelFault::Gain { .. }) => {
                        fields.push(("why", V::W("gain")))
                    }
                    ControlRefusal::Design { error, tries } => {
                        let word = match error {
                            DesignError::Spec => "spec",
                            DesignError::Singular => "singular",
                            DesignError::SlowPoles => "slow-poles",
                            DesignError::Poles => "poles",
                            DesignError::Margin { margin } => {
                                fields.push(("margin", f(margin)));
                                "margin"
                            }
                        };
                        fields.push(("why", V::W(word)));
                        fields.push(("tries", int(tries)));
                    }
                }
            }
            exp("REID", &[], fields)
        }
        Event::Fault(r) => {
            let (words, fields) = fault(r);
            exp("FAULT", &words, fields)
        }
    }
}

/// Re-estimates on the printed grid: one of each verdict, the figures a verdict has none of NaN.
fn reids() -> Vec<ReidReport> {
    let all = [
        ReidVerdict::Accepted,
        ReidVerdict::Kept,
        ReidVerdict::NotExcited,
        ReidVerdict::Model,
        ReidVerdict::Fit,
        ReidVerdict::Numeric,
        ReidVerdict::Design(ControlRefusal::Design {
            error: DesignError::Margin { margin: 0.375 },
            tries: 4,
        }),
        ReidVerdict::Design(ControlRefusal::Design {
            error: DesignError::SlowPoles,
            tries: 1,
        }),
        ReidVerdict::Design(ControlRefusal::Model(ModelFault::Unstable)),
        ReidVerdict::Design(ControlRefusal::Model(ModelFault::Gain { gain: 0.25 })),
    ];
    all.iter()
        .enumerate()
        .map(|(k, &verdict)| {
            let scored = matches!(
                verdict,
                ReidVerdict::Accepted | ReidVerdict::Kept | ReidVerdict::Fit
            );
            ReidReport {
                breath: 12 + k as u32,
                verdict,
                gain: if verdict == ReidVerdict::Numeric {
                    f32::NAN
                } else {
                    1.125
                },
                fit: if scored { 92.5 } else { f32::NAN },
                running: if scored { 60.5 } else { f32::NAN },
                v_rms: 22.125,
            }
        })
        .collect()
}

#[test]
fn reid_lines_parse_back_equal() {
    for r in reids() {
        let t = text(&Event::Reid(r));
        check(&t, &expected(&Event::Reid(r)));
        let p = ReidLine::parse(&t).unwrap_or_else(|e| panic!("{t}: {e:?}"));
        assert_eq!(p.breath, r.breath, "{t}");
        assert_eq!(p.verdict, r.verdict.name(), "{t}");
        assert!(ReidLine::VERDICTS.contains(&p.verdict.as_str()), "{t}");
        let same = |a: f64, b: f32| a == f64::from(b) || (a.is_nan() && b.is_nan());
        assert!(
            same(p.gain, r.gain) && same(p.fit, r.fit) && same(p.running, r.running),
            "{t}"
        );
        assert_eq!(p.v_rms, 22.125, "{t}");
        let (why, margin, tries) = match r.verdict {
            ReidVerdict::Design(ControlRefusal::Design { error, tries }) => match error {
                DesignError::Margin { margin } => ("margin", Some(f64::from(margin)), Some(tries)),
                DesignError::SlowPoles => ("slow-poles", None, Some(tries)),
                e => panic!("not in reids(): {e:?}"),
            },
            ReidVerdict::Design(ControlRefusal::Model(ModelFault::Unstable)) => {
                ("unstable", None, None)
            }
            ReidVerdict::Design(ControlRefusal::Model(ModelFault::Gain { .. })) => {
                ("gain", None, None)
            }
            ReidVerdict::Design(why) => panic!("not in reids(): {why:?}"),
            _ => ("", None, None),
        };
        assert_eq!(p.why.as_deref(), Some(why).filter(|w| !w.is_empty()), "{t}");
        assert_eq!(p.margin, margin, "{t}");
        assert_eq!(p.tries, tries.map(u32::from), "{t}");
    }
    assert_eq!(
        text(&Event::Reid(reids()[6])),
        "REID breath=18 verdict=design gain=1.125 fit=nan/nan v-rms=22.125 why=margin \
         margin=0.375 tries=4"
    );
    // `why=` only with `verdict=design`, and required there.
    assert!(ReidLine::parse(
        "REID breath=3 verdict=kept gain=1.000 fit=90.0/80.0 v-rms=5.000 why=margin"
    )
    .is_err());
    assert!(
        ReidLine::parse("REID breath=3 verdict=design gain=1.000 fit=nan/nan v-rms=nan").is_err()
    );
    assert_eq!(
        text(&Event::Reid(reids()[1])),
        "REID breath=13 verdict=kept gain=1.125 fit=92.5/60.5 v-rms=22.125"
    );
    // A verdict the firmware does not print, and a fit without the running model's.
    assert!(
        ReidLine::parse("REID breath=3 verdict=maybe gain=1.000 fit=90.0/80.0 v-rms=5.000")
            .is_err()
    );
    assert_eq!(
        ReidLine::parse("REID breath=3 verdict=kept gain=1.000 fit=90.0 v-rms=5.000"),
        Err(LineError::Field {
            key: "fit",
            expected: "number"
        })
    );
}

/// A breath on the printed grid: volumes in halves of a mL, the peak a multiple of 3 counts,
/// the RMS 0.5 slm (Σ 4 · 0.25 over 4 ticks).
fn breath() -> BreathSummary {
    BreathSummary {
        number: 17,
        tidal: 500.0,
        peep: 5.5,
        delivered: 487.5,
        command: 512.5,
        peak: 3_771,
        sum_sq: 1.0,
        samples: 4,
    }
}

/// One event of every kind and every reason, with values on the printed grid.
fn events() -> Vec<Event> {
    let stats = SearchStats {
        score: -1234.5,
        candidates: 252,
        evaluated: 14,
        skipped: 2,
        iterations: 200,
        samples: 2994,
    };
    // Means 0.25 (rms 0.5), -0.125, 50.125 slm over 8 samples.
    let res = Residuals {
        sum: -1.0,
        sum_sq: 2.0,
        sum_flow: 401.0,
        samples: 8,
    };
    let mut v = vec![
        Event::StoredRejected(StoredReason::Fit {
            fit: -1000.0,
            min: 70.0,
        }),
        Event::StoredRejected(StoredReason::MapSlope { slope: 0.5 }),
        Event::Loaded {
            model: model(),
            fit: 87.5,
        },
        Event::Scan {
            samples: 441,
            lag: 20,
            u0: 3000,
            y0: 2289,
            attempt: 1,
            attempts: 3,
        },
        Event::Map(map()),
        Event::Map(
            InputMap::new(
                0,
                1,
                [
                    -32_768, -32_767, -9, -8, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 32_767,
                ],
            )
            .unwrap(),
        ),
        Event::Excite {
            samples: 700,
            u0: 3000,
            y0: 2289,
            attempt: 1,
            attempts: 3,
        },
        Event::Excite {
            samples: 17,
            u0: 1,
            y0: -2289,
            attempt: 3,
            attempts: 3,
        },
        Event::Identified {
            model: model(),
            stats,
        },
        Event::Identified {
            model: ArxModel::new(&[0.5], &[0.25], 0, Offset::None, 0.0).unwrap(),
            stats,
        },
        Event::Validate { samples: 300 },
        Event::Accepted {
            fit: 87.5,
            rmse: 3.25,
            one_step: 2.125,
            samples: 2994,
        },
        Event::Control {
            tau: 0.25,
            alpha: 0.875,
            beta: 0.5,
            gamma: 0.875,
            kept: 4,
            margin: 0.625,
            tries: 1,
            preview: 8,
        },
        Event::Track {
            sum_setpoint: 160.0,
            sum_flow: 159.5,
            sum_sq: 1.0,
            max: 1.25,
            sum_duty: 14_080,
            samples: 4,
            tick: 1050,
        },
        Event::Alarm {
            on: true,
            error: 5.125,
            ticks: 50,
        },
        Event::Alarm {
            on: false,
            error: 0.0,
            ticks: 0,
        },
        Event::Residual(res),
        Event::Drift {
            residuals: res,
            seconds: 3,
            reidentify: false,
        },
        Event::Drift {
            residuals: res,
            seconds: 5,
            reidentify: true,
        },
        Event::Breath(breath()),
        Event::VolumeAlarm {
            on: true,
            delivered: 612.5,
            tidal: 500.0,
        },
        Event::VolumeAlarm {
            on: false,
            delivered: 0.0,
            tidal: 500.0,
        },
    ];
    v.extend(reids().into_iter().map(Event::Reid));
    for e in [
        PersistError::Length,
        PersistError::Magic,
        PersistError::Version,
        PersistError::Crc,
        PersistError::Structure,
        PersistError::NonFinite,
    ] {
        v.push(Event::StoredRejected(StoredReason::Record(e)));
    }
    let model_faults = [
        ModelFault::NonFinite,
        ModelFault::Unstable,
        ModelFault::Gain { gain: -3.125 },
    ];
    for m in model_faults {
        v.push(Event::StoredRejected(StoredReason::Model(m)));
        v.push(Event::Fault(FaultReason::Control(ControlRefusal::Model(m))));
    }
    for e in [
        CoreError::NonFinite,
        CoreError::Overflow,
        CoreError::TooShort {
            needed: 10,
            have: 3,
        },
        CoreError::InvalidStructure,
        CoreError::InvalidParameter,
        CoreError::NotExcited,
        CoreError::NotPositiveDefinite,
        CoreError::NoCandidate,
    ] {
        v.push(Event::Rejected {
            reason: RejectReason::Search(e),
            attempt: 1,
            attempts: 3,
        });
    }
    for reason in [
        RejectReason::NotExcited { rms: 0.125 },
        RejectReason::Map(MapError::Unscanned),
        RejectReason::Map(MapError::NotIncreasing),
        RejectReason::Map(MapError::Grid),
        RejectReason::Fit {
            fit: 42.5,
            min: 70.0,
        },
        RejectReason::NonFinite,
        RejectReason::SensorGaps { gaps: 11 },
    ] {
        v.push(Event::Rejected {
            reason,
            attempt: 2,
            attempts: 3,
        });
    }
    for error in [
        DesignError::Spec,
        DesignError::Singular,
        DesignError::SlowPoles,
        DesignError::Poles,
        DesignError::Margin { margin: 0.375 },
    ] {
        v.push(Event::Fault(FaultReason::Control(ControlRefusal::Design {
            error,
            tries: 5,
        })));
    }
    for e in [SensorFault::Nack, SensorFault::Crc, SensorFault::Bus] {
        v.push(Event::Fault(FaultReason::Sensor { error: e, count: 5 }));
    }
    v.extend(
        [
            FaultReason::FlowRange { counts: -31_245 },
            FaultReason::Stall {
                duty: 4500,
                counts: 15,
            },
            FaultReason::Frozen { counts: 2289 },
            FaultReason::NoFlow {
                duty: 3000,
                counts: 15,
                expected: 2289,
            },
            FaultReason::ResetLoop {
                watchdog: 2,
                brownout: 1,
            },
            FaultReason::Unidentified { attempts: 3 },
        ]
        .map(Event::Fault),
    );
    v
}

#[test]
fn every_event_parses_back_to_its_values() {
    for e in events() {
        check(&text(&e), &expected(&e));
    }
}

#[test]
fn breath_and_volume_alarm_lines_parse_back_equal() {
    let b = breath();
    assert_eq!(
        BreathLine::parse(&text(&Event::Breath(b))),
        Ok(BreathLine {
            number: 17,
            tidal: 500.0,
            peep: 5.5,
            delivered: 487.5,
            command: 512.5,
            peak: 3_771.0 / 120.0,
            rms: 0.5,
        })
    );
    let on = Event::VolumeAlarm {
        on: true,
        delivered: 612.5,
        tidal: 500.0,
    };
    assert_eq!(
        VolumeAlarmLine::parse(&text(&on)),
        Ok(VolumeAlarmLine::On {
            delivered: 612.5,
            tidal: 500.0
        })
    );
    let off = Event::VolumeAlarm {
        on: false,
        delivered: 612.5,
        tidal: 500.0,
    };
    assert_eq!(
        VolumeAlarmLine::parse(&text(&off)),
        Ok(VolumeAlarmLine::Clear)
    );
    // The tracking alarm is another line.
    let track = Event::Alarm {
        on: false,
        error: 0.0,
        ticks: 0,
    };
    assert!(VolumeAlarmLine::parse(&text(&track)).is_err());
    // A BREATH line missing a field names it.
    assert_eq!(
        BreathLine::parse("BREATH n=1 vt=500.0 peep=5.0 vd=497.2 cmd=500.0 peak=31.250"),
        Err(LineError::Field {
            key: "rms",
            expected: "number"
        })
    );
}

#[test]
fn id_line_parses_back_equal() {
    for e in events() {
        let Event::Identified { model, stats } = e else {
            continue;
        };
        let id = IdLine::parse(&text(&e)).unwrap();
        assert_eq!(
            id,
            IdLine {
                model: printed(&model),
                score: f64::from(stats.score),
                evaluated: stats.evaluated,
                candidates: stats.candidates,
                skipped: stats.skipped,
                iterations: stats.iterations,
            }
        );
        // The model it prints is the model it was made of.
        let back = id.model.arx().unwrap();
        assert_eq!(back.structure(), model.structure());
        assert_eq!(back.offset(), model.offset());
    }
}

#[test]
fn loaded_and_model_lines_share_the_model() {
    let e = Event::Loaded {
        model: model(),
        fit: 87.5,
    };
    let l = LoadedLine::parse(&text(&e)).unwrap();
    assert_eq!(
        l,
        LoadedLine {
            model: printed(&model()),
            fit: 87.5
        }
    );
    // The console's MODEL answer prints the same fields.
    let mut s = heapless::String::<LINE_MAX>::new();
    let m = model();
    ufmt::uwrite!(
        s,
        "{}",
        ridge_pump_firmware::console::ModelLine {
            model: Some((&m, 87.5))
        }
    )
    .unwrap();
    let p = ParsedLine::parse(&s);
    assert_eq!(p.keyword, "MODEL");
    assert_eq!(PrintedModel::from_line(&p), Ok(printed(&m)));
}

#[test]
fn scan_map_excite_and_validate_lines_parse_back_equal() {
    let mut kinds = 0;
    for e in events() {
        match e {
            Event::Scan {
                samples,
                lag,
                u0,
                y0,
                attempt,
                attempts,
            } => {
                let x = ScanLine::parse(&text(&e)).unwrap();
                assert_eq!(
                    x,
                    ScanLine {
                        samples: samples.into(),
                        lag,
                        u0,
                        y0,
                        attempt: (attempt, attempts),
                    }
                );
                kinds |= 1;
            }
            Event::Map(map) => {
                assert_eq!(MapLine::parse(&text(&e)), Ok(MapLine { map }));
                kinds |= 2;
            }
            Event::Excite {
                samples,
                u0,
                y0,
                attempt,
                attempts,
            } => {
                let x = ExciteLine::parse(&text(&e)).unwrap();
                assert_eq!(
                    x,
                    ExciteLine {
                        record: RECORD_NAME.to_owned(),
                        samples,
                        u0,
                        y0,
                        attempt: Some((attempt, attempts)),
                    }
                );
                let (u, y) = x.operating_point();
                assert_eq!(u, f64::from(u0) / 10_000.0);
                assert_eq!(y, f64::from(y0) / 120.0);
                kinds |= 4;
            }
            Event::Validate { samples } => {
                assert_eq!(
                    ValidateLine::parse(&text(&e)),
                    Ok(ValidateLine {
                        record: RECORD_NAME.to_owned(),
                        samples
                    })
                );
                kinds |= 8;
            }
            _ => {}
        }
    }
    assert_eq!(kinds, 15, "every kind was in the events");
}

/// Every map knot the line can carry (any `i16` count, strictly increasing) reads back as
/// that count, and a line that is not a map is refused naming its field.
#[test]
fn map_lines_are_exact_for_every_count_and_refuse_what_is_not_a_map() {
    for start in (i16::MIN..=i16::MAX - 16).step_by(13) {
        let mut knots = [0i16; MAP_KNOTS];
        for (k, v) in knots.iter_mut().enumerate() {
            *v = start + k as i16;
        }
        let map = InputMap::new(1_500, 533, knots).unwrap();
        let back = MapLine::parse(&text(&Event::Map(map))).unwrap().map;
        assert_eq!(back, map);
    }
    let good = text(&Event::Map(map()));
    // 15 flows, a decreasing pair, a zero spacing, a word where a number goes.
    let short = good.rsplit_once(',').unwrap().0.to_owned();
    assert_eq!(
        MapLine::parse(&short),
        Err(LineError::Length {
            key: "flow",
            expected: 16,
            found: 15
        })
    );
    let swapped = good.replacen("flow=", "flow=999.000,", 1);
    let swapped = swapped.rsplit_once(',').unwrap().0.to_owned();
    assert!(matches!(
        MapLine::parse(&swapped),
        Err(LineError::Field { key: "flow", .. })
    ));
    let zero = good.replacen("step=5.33", "step=0.00", 1);
    assert!(MapLine::parse(&zero).is_err());
    assert_eq!(
        MapLine::parse(&good.replacen("first=15.00", "first=x", 1)),
        Err(LineError::Field {
            key: "first",
            expected: "number"
        })
    );
}

/// Every whole count of 1/120 slm the line can carry prints (as milli-slm) and reads back as
/// that count: `y0` is exact although 1/120 slm has no finite decimal.
#[test]
fn excite_operating_point_is_exact_for_every_count() {
    for y0 in (i16::MIN..=i16::MAX)
        .step_by(7)
        .chain([i16::MIN, -1, 0, 1, i16::MAX])
    {
        for u0 in [0, 1, 3333, 9999, 10_000] {
            let e = Event::Excite {
                samples: 3000,
                u0,
                y0,
                attempt: 1,
                attempts: 3,
            };
            let x = ExciteLine::parse(&text(&e)).unwrap();
            assert_eq!((x.u0, x.y0), (u0, y0), "{}", text(&e));
        }
    }
}

/// Values off the printed grid: each parsed number lies within half a unit of the last printed
/// digit of the exact value (plus the f32 rounding of the writer's means).
#[test]
fn values_off_the_grid_parse_within_half_a_digit() {
    let m = ArxModel::new(
        &[0.9351234],
        &[6.4999996, -0.1],
        2,
        Offset::Intercept,
        -0.12345,
    )
    .unwrap();
    let id = Event::Identified {
        model: m,
        stats: SearchStats {
            score: -1234.56,
            candidates: 252,
            evaluated: 14,
            skipped: 0,
            iterations: 200,
            samples: 3000,
        },
    };
    let p = IdLine::parse(&text(&id)).unwrap();
    let near = |got: f64, want: f32, digits: i32| {
        let half = 0.5 * 10f64.powi(-digits);
        assert!(
            (got - f64::from(want)).abs() <= half * (1.0 + 1e-9),
            "{got} vs {want} ({digits} digits)"
        );
    };
    for (g, w) in p.model.theta.iter().zip(m.theta()) {
        near(*g, *w, 6);
    }
    for (g, w) in p.model.phi.iter().zip(m.phi()) {
        near(*g, *w, 6);
    }
    near(p.model.c, m.intercept(), 6);
    near(p.score, -1234.56, 1);
    let track = Event::Track {
        sum_setpoint: 4000.1,
        sum_flow: 3987.77,
        sum_sq: 26.3,
        max: 1.2345,
        sum_duty: 352_049,
        samples: 100,
        tick: 1050,
    };
    let t = ParsedLine::parse(&text(&track));
    let mean = |x: f32| (f64::from(x) / 100.0) as f32;
    // The writer's means are f32 products (sum · 1/n): allow their rounding too.
    let near_mean = |got: f64, want: f64| {
        assert!(
            (got - want).abs() <= 0.5e-3 + 1e-6 * want.abs(),
            "{got} vs {want}"
        );
    };
    near_mean(t.num("sp").unwrap(), f64::from(mean(4000.1)));
    near_mean(t.num("flow").unwrap(), f64::from(mean(3987.77)));
    near_mean(t.num("rms").unwrap(), (26.3f64 / 100.0).sqrt());
    near(t.num("max").unwrap(), 1.2345, 3);
    // Mean duty 3520.49 → 3520 (1/10 000) → 35.20 %.
    assert_eq!(t.num("duty"), Some(35.2));
}

#[test]
fn numbers_follow_the_writers_grammar() {
    assert_eq!(number("0"), Some(0.0));
    assert_eq!(number("-19.058"), Some(-19.058));
    assert_eq!(number("4294.96729"), Some(4294.96729));
    assert_eq!(number("inf"), Some(f64::INFINITY));
    assert_eq!(number("-inf"), Some(f64::NEG_INFINITY));
    assert!(number("nan").is_some_and(f64::is_nan));
    for bad in [
        "", "-", "+1", "1e3", ".5", "5.", "1.2.3", "ovf", "NaN", " 1", "1,5", "0x10",
    ] {
        assert_eq!(number(bad), None, "{bad:?}");
    }
    let p = ParsedLine::parse("X a=1/3 b=42.5<70.0 c=12% d= e=- f=1,x g=+2");
    assert_eq!(p.int("a"), Some(1));
    assert_eq!(p.ratio("a"), Some((1, 3)));
    assert_eq!(p.num("b"), Some(42.5));
    assert_eq!(p.num("c"), Some(12.0));
    assert_eq!(p.list("d"), Some(vec![]));
    assert_eq!(p.list("e"), Some(vec![]));
    assert_eq!(p.list("f"), None);
    assert_eq!(p.num("g"), None);
    assert_eq!(p.num("missing"), None);
}

#[test]
fn malformed_lines_name_the_field() {
    let id = text(&Event::Identified {
        model: model(),
        stats: SearchStats {
            score: 1.5,
            candidates: 252,
            evaluated: 14,
            skipped: 0,
            iterations: 7,
            samples: 3000,
        },
    });
    assert_eq!(
        IdLine::parse(&id.replace("ID ", "LOADED ")),
        Err(LineError::Keyword { expected: "ID" })
    );
    let without = |key: &str| {
        id.split(' ')
            .filter(|w| !w.starts_with(&format!("{key}=")))
            .collect::<Vec<_>>()
            .join(" ")
    };
    for key in [
        "p", "q", "d", "off", "theta", "phi", "c", "score", "eval", "skip", "iters",
    ] {
        let err = IdLine::parse(&without(key)).unwrap_err();
        assert!(
            matches!(err, LineError::Field { key: k, .. } if k == key),
            "{key}: {err:?}"
        );
    }
    // θ with fewer entries than p says; a non-finite coefficient; off neither 0 nor 1.
    assert_eq!(
        IdLine::parse(&id.replace("theta=0.937500,-0.125000", "theta=0.937500")),
        Err(LineError::Length {
            key: "theta",
            expected: 2,
            found: 1
        })
    );
    assert!(matches!(
        IdLine::parse(&id.replace("phi=6.500000", "phi=nan")),
        Err(LineError::Field { key: "phi", .. })
    ));
    assert!(matches!(
        IdLine::parse(&id.replace("off=1", "off=2")),
        Err(LineError::Field { key: "off", .. })
    ));
    let err = ExciteLine::parse("EXCITE A-Multistep n=3.5 u0=30.00 y0=19.058").unwrap_err();
    assert_eq!(err.to_string(), "no whole number n=");
    let err = ExciteLine::parse("EXCITE A-Multistep n=30 u0=x y0=19.058").unwrap_err();
    assert_eq!(err.to_string(), "no number u0=");
    assert_eq!(
        ExciteLine::parse("EXCITE n=30 u0=30.00 y0=19.058"),
        Err(LineError::NoRecord)
    );
    // The attempt is optional (the rest of the line is what the host needs).
    assert_eq!(
        ExciteLine::parse("EXCITE A-Multistep n=30 u0=30.00 y0=19.058").map(|x| x.attempt),
        Ok(None)
    );
}
