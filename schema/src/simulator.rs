//! A rig's `[simulator]`: which simulator runs behind the bridge protocol, and its task.

use std::fmt;

use serde::{Deserialize, Serialize};

/// Which simulator a rig stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SimulatorKind {
    /// MetaWorld 3.1 (one of its 50 tasks).
    Metaworld,
    /// gym-aloha's bimanual tasks.
    Aloha,
}

impl fmt::Display for SimulatorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Metaworld => "metaworld",
            Self::Aloha => "aloha",
        })
    }
}

/// A rig's `[simulator]`: the simulator and task the bridge runs for it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Simulator {
    /// The simulator.
    pub bridge: SimulatorKind,
    /// Its task, by the simulator's name (`assembly`, `transfer-cube`).
    pub task: String,
}
