//! The pieces a benchmark's table and plot are made of: a task's level in MetaWorld's order,
//! and a result's cell (success, interval, and a mark when an older bridge scored it).

use scaledp_schema::benchmarks::Difficulty;

use crate::figures::EvalFigures;

/// A task's level: MetaWorld's difficulty levels in their order, any other label (ALOHA's
/// `bimanual`) after them.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Level {
    rank: usize,
    pub(super) label: String,
}

pub(super) fn level_of(label: &str) -> Level {
    let rank = Difficulty::ALL
        .iter()
        .position(|d| d.label() == label)
        .unwrap_or(Difficulty::ALL.len());
    Level {
        rank,
        label: label.to_string(),
    }
}

pub(super) fn pct(f: &EvalFigures) -> String {
    format!(
        "{:.0} % ({}/{}, {:.0}–{:.0})",
        100.0 * f.success_rate,
        f.successes,
        f.episodes,
        100.0 * f.wilson_low,
        100.0 * f.wilson_high
    )
}

/// The bridge behaviour that scored `f` (1 when it was scored before bridges reported one).
pub(super) fn behaviour(f: &EvalFigures) -> u32 {
    f.bridge
        .as_deref()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
}

/// `pct`, marked ` †` when an older bridge than `newest` scored it.
pub(super) fn marked(f: &EvalFigures, newest: u32) -> String {
    let mark = if behaviour(f) < newest { " †" } else { "" };
    format!("{}{mark}", pct(f))
}
