//! What a scoring pass keeps for the plot: measured and predicted output decimated to a
//! bounded min/max envelope ([`Trace`], [`Envelope`]).

/// Points a [`Trace`] of a run keeps per signal for the plot.
pub const PLOT_POINTS: usize = 2000;

/// A bounded picture of one signal for plotting: every sample while the record has at
/// most `max_points` samples, otherwise the minimum and maximum of each of
/// `max_points / 2` equal buckets (a min/max envelope, so spikes stay visible).
#[derive(Debug, Clone, Default)]
pub struct Envelope {
    /// One entry per bucket in index order: `(first sample index, min, max)`; without
    /// decimation every bucket is one sample and `min == max`.
    pub buckets: Vec<(f64, f64, f64)>,
    current: Option<Bucket>,
}

/// The open bucket of an [`Envelope`].
#[derive(Debug, Clone, Copy)]
struct Bucket {
    id: u64,
    first: u64,
    lo: f64,
    hi: f64,
}

impl Envelope {
    fn push(&mut self, bucket: u64, i: u64, v: f64) {
        if !v.is_finite() {
            return;
        }
        let b = i / bucket.max(1);
        match &mut self.current {
            Some(c) if c.id == b => {
                c.lo = c.lo.min(v);
                c.hi = c.hi.max(v);
            }
            _ => {
                self.flush();
                self.current = Some(Bucket {
                    id: b,
                    first: i,
                    lo: v,
                    hi: v,
                });
            }
        }
    }

    fn flush(&mut self) {
        if let Some(c) = self.current.take() {
            self.buckets.push((c.first as f64, c.lo, c.hi));
        }
    }

    /// Smallest and largest value, if any.
    pub fn range(&self) -> Option<(f64, f64)> {
        self.buckets
            .iter()
            .fold(None, |acc, &(_, lo, hi)| match acc {
                None => Some((lo, hi)),
                Some((a, b)) => Some((a.min(lo), b.max(hi))),
            })
    }

    /// The lower outline `(index, min)`: the signal itself when not decimated.
    pub fn lower(&self) -> Vec<(f64, f64)> {
        self.buckets.iter().map(|&(x, lo, _)| (x, lo)).collect()
    }

    /// The upper outline `(index, max)`.
    pub fn upper(&self) -> Vec<(f64, f64)> {
        self.buckets.iter().map(|&(x, _, hi)| (x, hi)).collect()
    }
}

/// Measured, one-step and free-run output of one record, decimated for a plot
/// (memory bounded by `max_points` per signal whatever the record length).
#[derive(Debug, Clone)]
pub struct Trace {
    /// Samples per bucket.
    bucket: u64,
    /// Samples pushed.
    pub samples: u64,
    /// Measured output.
    pub measured: Envelope,
    /// One-step-ahead prediction (from sample `m` on).
    pub one_step: Envelope,
    /// Free-run simulation (from sample `m` on).
    pub free_run: Envelope,
}

impl Trace {
    /// A trace for a record of `total` samples keeping about `max_points` points per
    /// signal (at least 4).
    pub fn new(total: u64, max_points: usize) -> Self {
        let max_points = max_points.max(4) as u64;
        let bucket = if total <= max_points {
            1
        } else {
            total.div_ceil(max_points / 2)
        };
        Trace {
            bucket,
            samples: 0,
            measured: Envelope::default(),
            one_step: Envelope::default(),
            free_run: Envelope::default(),
        }
    }

    /// Adds sample `i`: the measurement and, once seeded, `(one-step, free-run)`.
    pub fn push(&mut self, i: u64, y: f64, pred: Option<(f64, f64)>) {
        self.samples = self.samples.max(i + 1);
        self.measured.push(self.bucket, i, y);
        if let Some((a, b)) = pred {
            self.one_step.push(self.bucket, i, a);
            self.free_run.push(self.bucket, i, b);
        }
    }

    /// Flushes the last bucket (call once after the last sample).
    pub fn finish(&mut self) {
        self.measured.flush();
        self.one_step.flush();
        self.free_run.flush();
    }

    /// `true` when the signals were decimated to a min/max envelope.
    pub fn decimated(&self) -> bool {
        self.bucket > 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_is_bounded_and_keeps_extremes() {
        let n = 1_000_000u64;
        let mut t = Trace::new(n, 2000);
        for i in 0..n {
            let y = if i == 123_457 {
                500.0
            } else {
                (i % 100) as f64
            };
            t.push(i, y, Some((y, y)));
        }
        t.finish();
        assert!(t.decimated());
        let b = &t.measured.buckets;
        assert!(b.len() <= 1001, "{}", b.len());
        // The one-sample spike survives decimation, and so do the extremes.
        assert_eq!(t.measured.range(), Some((0.0, 500.0)));
        assert_eq!(
            t.measured.upper().iter().filter(|p| p.1 == 500.0).count(),
            1
        );
        assert!(t.measured.lower().iter().all(|p| p.1 == 0.0));
        let mut t = Trace::new(10, 2000);
        for i in 0..10 {
            t.push(i, i as f64, None);
        }
        t.finish();
        assert_eq!(t.measured.lower(), t.measured.upper());
        assert_eq!(t.measured.buckets.len(), 10);
        assert!(t.one_step.buckets.is_empty());
    }
}
