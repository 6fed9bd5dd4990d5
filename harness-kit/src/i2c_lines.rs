//! The I2C lines at the pin level, as both harnesses model them beside their emulator's I2C
//! peripheral (which moves bytes and never drives the pins): the pull-ups (a line is high
//! unless something drives it low), a slave holding SDA low ([`SdaHold`], armed, begun at a
//! STOP, let go after its clocks), and what the lines did ([`BusEvent`], time-stamped in the
//! harness's own unit: simavr core cycles, stm32 picoseconds). Each harness feeds it from its
//! own pins and registers (which writes are a STOP request, which START is blocked).
//!
//! A slave stuck in a byte drives one bit per SCL clock and lets go of SDA after the rest of its
//! byte and the acknowledge slot, i.e. after at most 9 clocks; START (SDA falls while SCL is
//! high) and STOP (SDA rises while SCL is high) are the conditions of NXP UM10204 §3.1.4.

/// How long the slave holds SDA low.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdaHold {
    /// Lets go at the k-th falling SCL edge after the hold began (k ≥ 1; a real slave needs at
    /// most 9: the rest of its byte and the acknowledge slot). `0` is taken as 1.
    ReleaseAfter(u8),
    /// Never lets go (a dead slave).
    Forever,
}

/// A change on the bus lines, with its time in the harness's unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusEvent {
    /// The slave started holding SDA low.
    Hold(u64),
    /// The firmware asked its I2C peripheral for a START while SDA was held: it never happens.
    BlockedStart(u64),
    /// SCL changed level (`true` = high).
    Scl(u64, bool),
    /// SDA changed level (`true` = high) on the wire.
    Sda(u64, bool),
    /// START condition on the pins: SDA fell while SCL was high.
    Start(u64),
    /// STOP condition on the pins: SDA rose while SCL was high.
    Stop(u64),
    /// The slave let go of SDA.
    Release(u64),
}

impl BusEvent {
    /// Time of the event, in the harness's unit.
    pub fn at(&self) -> u64 {
        match *self {
            BusEvent::Hold(t)
            | BusEvent::BlockedStart(t)
            | BusEvent::Scl(t, _)
            | BusEvent::Sda(t, _)
            | BusEvent::Start(t)
            | BusEvent::Stop(t)
            | BusEvent::Release(t) => t,
        }
    }
}

/// The two lines' levels on the wire, the slave's hold, and everything they did.
#[derive(Debug)]
pub struct Lines {
    armed: Option<SdaHold>,
    /// The hold in force and the falling SCL edges since it began.
    holding: Option<(SdaHold, u8)>,
    scl: bool,
    sda: bool,
    /// Everything seen so far, in order.
    pub events: Vec<BusEvent>,
}

impl Default for Lines {
    /// An idle bus: both lines high, nothing armed, nothing seen.
    fn default() -> Self {
        Lines {
            armed: None,
            holding: None,
            scl: true,
            sda: true,
            events: Vec::new(),
        }
    }
}

impl Lines {
    /// Arms a hold: it begins at the next [`begin_hold`](Self::begin_hold) (the harness calls
    /// it at the STOP its board's I2C peripheral is asked for or sends).
    pub fn arm(&mut self, hold: SdaHold) {
        self.armed = Some(hold);
    }

    /// Whether the slave holds SDA low now.
    pub fn holding(&self) -> bool {
        self.holding.is_some()
    }

    /// The levels on the wire: (SCL, SDA), `true` = high.
    pub fn levels(&self) -> (bool, bool) {
        (self.scl, self.sda)
    }

    /// Clock pulses (falling SCL edges) in `from..to`.
    pub fn scl_pulses(&self, from: u64, to: u64) -> usize {
        self.events
            .iter()
            .filter(|e| matches!(e, BusEvent::Scl(t, false) if (from..to).contains(t)))
            .count()
    }

    /// Times of the events `want` picks out, in order.
    pub fn times(&self, want: impl Fn(&BusEvent) -> bool) -> Vec<u64> {
        self.events
            .iter()
            .filter(|e| want(e))
            .map(BusEvent::at)
            .collect()
    }

    /// The SCL phases that begin in `from..to` and end at the next SCL edge: (start, high,
    /// length), lengths in the harness's unit. The last edge in the span opens no phase.
    pub fn scl_phases(&self, from: u64, to: u64) -> Vec<(u64, bool, u64)> {
        let edges: Vec<(u64, bool)> = self
            .events
            .iter()
            .filter_map(|e| match *e {
                BusEvent::Scl(t, high) if (from..to).contains(&t) => Some((t, high)),
                _ => None,
            })
            .collect();
        edges
            .windows(2)
            .map(|w| (w[0].0, w[0].1, w[1].0 - w[0].0))
            .collect()
    }

    /// SCL is `high` on the wire at `now` (nothing if it already was); returns whether the
    /// slave lets go of SDA at this edge (its k-th falling edge of [`SdaHold::ReleaseAfter`]).
    pub fn scl(&mut self, now: u64, high: bool) -> bool {
        if high == self.scl {
            return false;
        }
        self.scl = high;
        self.events.push(BusEvent::Scl(now, high));
        let Some((hold, edges)) = &mut self.holding else {
            return false;
        };
        if high {
            return false;
        }
        *edges = edges.saturating_add(1);
        if !matches!(*hold, SdaHold::ReleaseAfter(k) if *edges >= k.max(1)) {
            return false;
        }
        self.holding = None;
        self.events.push(BusEvent::Release(now));
        true
    }

    /// The master leaves SDA high (`released`) or drives it low at `now`: the wire's level is
    /// high only if the slave does not hold it. Returns whether a STOP condition happened.
    pub fn sda(&mut self, now: u64, released: bool) -> bool {
        let high = released && self.holding.is_none();
        if high == self.sda {
            return false;
        }
        self.sda = high;
        self.events.push(BusEvent::Sda(now, high));
        if self.scl {
            self.events.push(if high {
                BusEvent::Stop(now)
            } else {
                BusEvent::Start(now)
            });
            return high;
        }
        false
    }

    /// The STOP that begins an armed hold, at `now`; returns whether one began. The slave
    /// drove its bit while SCL was low, so SDA's fall makes no START condition.
    pub fn begin_hold(&mut self, now: u64) -> bool {
        let Some(hold) = self.armed.take() else {
            return false;
        };
        self.holding = Some((hold, 0));
        self.events.push(BusEvent::Hold(now));
        self.sda = false;
        true
    }

    /// The firmware asked for a START at `now` while SDA was held.
    pub fn blocked_start(&mut self, now: u64) {
        self.events.push(BusEvent::BlockedStart(now));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// UM10204 §3.1.4: SDA falling while SCL is high is a START, rising a STOP; with SCL low
    /// neither.
    #[test]
    fn start_and_stop_are_sda_edges_while_scl_is_high() {
        let mut l = Lines::default();
        assert!(!l.sda(1, false));
        assert!(!l.scl(2, false));
        assert!(!l.sda(3, true));
        assert!(!l.sda(4, false));
        assert!(!l.scl(5, true));
        assert!(l.sda(6, true));
        assert_eq!(l.times(|e| matches!(e, BusEvent::Start(_))), vec![1]);
        assert_eq!(l.times(|e| matches!(e, BusEvent::Stop(_))), vec![6]);
        assert_eq!(l.levels(), (true, true));
    }

    /// A slave that lost its clock lets go at the k-th falling SCL edge after the hold, not
    /// before; while it holds, the master's released SDA stays low; a dead slave never lets go.
    #[test]
    fn a_held_sda_is_released_after_k_clocks() {
        for k in [1u8, 5, 9] {
            let mut l = Lines::default();
            assert!(!l.begin_hold(0), "nothing armed");
            l.arm(SdaHold::ReleaseAfter(k));
            assert!(l.begin_hold(10));
            assert!(!l.sda(11, true), "held low");
            assert_eq!(l.levels(), (true, false));
            let mut released_at = None;
            for n in 1..=12u64 {
                assert!(!l.scl(100 * n, true));
                if l.scl(100 * n + 50, false) {
                    released_at.get_or_insert(n);
                }
            }
            assert_eq!(released_at, Some(u64::from(k)), "k = {k}");
            assert_eq!(l.scl_pulses(0, 100 * u64::from(k) + 51), usize::from(k));
            assert!(!l.holding());
        }
        let mut l = Lines::default();
        l.arm(SdaHold::Forever);
        assert!(l.begin_hold(0));
        assert!((1..100u64).all(|n| !l.scl(2 * n, n % 2 == 0)));
        assert!(l.holding());
    }

    /// The SCL phases are the spans between consecutive edges, with the level that opened them.
    #[test]
    fn scl_phases_are_the_spans_between_edges() {
        let mut l = Lines::default();
        for (t, high) in [(10, false), (25, true), (31, false), (60, true)] {
            l.scl(t, high);
        }
        assert_eq!(
            l.scl_phases(0, 100),
            vec![(10, false, 15), (25, true, 6), (31, false, 29)]
        );
        assert_eq!(l.scl_phases(20, 40), vec![(25, true, 6)]);
    }
}
