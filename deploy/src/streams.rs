//! One input stream of the controller: stamps (ascending, about a second of them), values, and
//! when it was last heard from on the receive clock.

use std::collections::VecDeque;

use scaledp_converter::live;

use crate::options::ControlOptions;

#[derive(Debug, Clone)]
pub(crate) struct Series {
    pub(crate) name: String,
    pub(crate) period_s: f64,
    pub(crate) stamps: VecDeque<u64>,
    values: VecDeque<Vec<f64>>,
    pub(crate) last_heard_ns: Option<u64>,
    keep: usize,
}

impl Series {
    /// A stream at `rate_hz` keeping about `keep_s` seconds of samples (never fewer than 4).
    pub(crate) fn new(name: String, rate_hz: f64, keep_s: f64) -> Self {
        Series {
            name,
            period_s: 1.0 / rate_hz,
            stamps: VecDeque::new(),
            values: VecDeque::new(),
            last_heard_ns: None,
            keep: ((keep_s * rate_hz).ceil() as usize).max(2) + 2,
        }
    }

    /// The same stream, emptied.
    pub(crate) fn cleared(&self) -> Self {
        Series {
            name: self.name.clone(),
            stamps: VecDeque::new(),
            values: VecDeque::new(),
            last_heard_ns: None,
            ..*self
        }
    }
    pub(crate) fn push(&mut self, stamp_ns: u64, recv_ns: u64, v: Vec<f64>) {
        self.last_heard_ns = Some(recv_ns);
        if self.stamps.back().is_some_and(|&s| s >= stamp_ns) {
            return; // out of order or repeated: the converter keeps stamps ascending
        }
        self.stamps.push_back(stamp_ns);
        self.values.push_back(v);
        while self.stamps.len() > self.keep {
            self.stamps.pop_front();
            self.values.pop_front();
        }
    }
    /// The converter's joint rule at `t_ns`, for ticks `tick_s` apart.
    pub(crate) fn at(&mut self, t_ns: u64, tick_s: f64) -> Option<Vec<f64>> {
        let s = self.stamps.make_contiguous();
        let v = self.values.make_contiguous();
        live::joints_at(s, v, self.period_s, tick_s, t_ns)
    }
    pub(crate) fn silence(&self, now_ns: u64, opts: &ControlOptions) -> Option<String> {
        let limit = (opts.stale_periods * self.period_s).max(opts.min_silence_s);
        match self.last_heard_ns {
            None => Some(format!("waiting for {}", self.name)),
            Some(t) if now_ns.saturating_sub(t) as f64 * 1e-9 > limit => Some(format!(
                "{} silent for {:.0} ms (limit {:.0} ms)",
                self.name,
                now_ns.saturating_sub(t) as f64 * 1e-6,
                limit * 1e3
            )),
            Some(_) => None,
        }
    }
}
