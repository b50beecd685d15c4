//! The comparison's arms: the recipe's model, the causal ablation, the next size up.

use scaledp_policy::{Attention, ModelSize};

/// One arm: a model size and an attention pattern, everything else the recipe's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Arm {
    /// Its name (`ti`, `ti-causal`, `s`): the run directory and result file are named by it.
    pub name: &'static str,
    /// The denoiser's size.
    pub size: ModelSize,
    /// The denoiser's attention.
    pub attention: Attention,
    /// One line for the table.
    pub what: &'static str,
}

/// Every arm, the recipe's first.
pub const ARMS: [Arm; 3] = [
    Arm {
        name: "ti",
        size: ModelSize::Ti,
        attention: Attention::NonCausal,
        what: "ScaleDP-Ti, non-causal attention (the recipe)",
    },
    Arm {
        name: "ti-causal",
        size: ModelSize::Ti,
        attention: Attention::Causal,
        what: "ScaleDP-Ti, causal attention (the DP-T-style ablation)",
    },
    Arm {
        name: "s",
        size: ModelSize::S,
        attention: Attention::NonCausal,
        what: "ScaleDP-S, non-causal attention",
    },
];

/// The arm named `name`.
pub fn arm(name: &str) -> Option<Arm> {
    ARMS.iter().copied().find(|a| a.name == name)
}
