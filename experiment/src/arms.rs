//! The comparison's arms: the recipe's model, the causal ablation, the next size up, and the
//! paper's baseline (DP-T) with the depths its scaling claim is about.

use scaledp_policy::{Architecture, Attention, ModelSize, PosEmbed, TrainOptions, DPT_DIMS};

/// One arm: a denoiser (architecture, size, depth, attention), everything else the recipe's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Arm {
    /// Its name (`ti`, `ti-causal`, `s`, `dp-t`, …): the run directory and result file are
    /// named by it.
    pub name: &'static str,
    /// The denoiser's architecture.
    pub arch: Architecture,
    /// The ScaleDP size (its depth, width and heads; unused by DP-T).
    pub size: ModelSize,
    /// A depth other than the size's (or DP-T's 8).
    pub layers: Option<usize>,
    /// The denoiser's attention.
    pub attention: Attention,
    /// ScaleDP's positional embedding (learned, as the paper's; DP-T keeps its own).
    pub pos_embed: PosEmbed,
    /// The recipe's optimizer steps times this (1; 3 for the budget arms, whose learning-rate
    /// schedule stretches over the longer run).
    pub steps_factor: u64,
    /// One line for the table.
    pub what: &'static str,
}

impl Arm {
    /// The claim that holding this arm against the recipe's (ScaleDP-Ti, non-causal) puts to
    /// the test, saying whose it is (the paper's, or this repo's own hypothesis); `None` for the
    /// recipe's own arm.
    pub fn claim(&self) -> Option<&'static str> {
        match self.name {
            "ti-causal" => {
                Some("the paper's: non-causal attention above causal (Ti above this arm)")
            }
            "s" => Some("the paper's: a larger ScaleDP does better (this arm above Ti)"),
            "dp-t" => Some("the paper's: ScaleDP-Ti above DP-T, its baseline"),
            "dp-t-l12" | "dp-t-l14" => Some("the paper's: ScaleDP-Ti above a deeper DP-T"),
            // Not the paper's: a hypothesis from the ALOHA results (docs/experiments.md).
            "ti-sincos" => {
                Some("this repo's: fixed positions lift non-causal Ti (this arm above it)")
            }
            "ti-learned-sincos" => Some(
                "this repo's: a learned pos_embed started at the tokens' scale lifts non-causal Ti (this arm above it)",
            ),
            "ti-x3" => Some("this repo's: non-causal Ti is short of steps (this arm above it)"),
            "ti-causal-x3" => {
                Some("this repo's: the mask's lead is the budget's (compare with ti-x3)")
            }
            _ => None,
        }
    }

    /// The arm other than the recipe's that a registered reading of `docs/experiments.md` holds
    /// this one against (reading 2, the budget: `ti-causal-x3` against `ti-x3`); `None` for the
    /// arms read against the recipe's only.
    pub fn also_against(&self) -> Option<&'static str> {
        match self.name {
            "ti-causal-x3" => Some("ti-x3"),
            _ => None,
        }
    }

    /// The recipe `base` with this arm's denoiser.
    pub fn options(&self, base: TrainOptions) -> TrainOptions {
        let steps = base.get_steps() * self.steps_factor;
        let o = base
            .steps(steps)
            .arch(self.arch)
            .model(self.size)
            .attention(self.attention)
            .pos_embed(self.pos_embed);
        match self.layers {
            Some(depth) => {
                let (_, width, heads) = match self.arch {
                    Architecture::ScaleDp => self.size.dims(),
                    Architecture::DpT => DPT_DIMS,
                };
                o.denoiser(depth, width, heads)
            }
            None => o,
        }
    }
}

const fn scaledp(
    name: &'static str,
    size: ModelSize,
    attention: Attention,
    what: &'static str,
) -> Arm {
    Arm {
        name,
        arch: Architecture::ScaleDp,
        size,
        layers: None,
        attention,
        pos_embed: PosEmbed::Learned,
        steps_factor: 1,
        what,
    }
}

const fn dpt(name: &'static str, layers: Option<usize>, what: &'static str) -> Arm {
    Arm {
        name,
        arch: Architecture::DpT,
        size: ModelSize::Ti,
        layers,
        attention: Attention::Causal,
        pos_embed: PosEmbed::Learned,
        steps_factor: 1,
        what,
    }
}

/// Every arm, the recipe's first.
pub const ARMS: [Arm; 10] = [
    scaledp(
        "ti",
        ModelSize::Ti,
        Attention::NonCausal,
        "ScaleDP-Ti, non-causal attention (the recipe)",
    ),
    scaledp(
        "ti-causal",
        ModelSize::Ti,
        Attention::Causal,
        "ScaleDP-Ti, causal attention (the DP-T-style ablation)",
    ),
    scaledp(
        "s",
        ModelSize::S,
        Attention::NonCausal,
        "ScaleDP-S, non-causal attention",
    ),
    Arm {
        pos_embed: PosEmbed::SinCos,
        ..scaledp(
            "ti-sincos",
            ModelSize::Ti,
            Attention::NonCausal,
            "ScaleDP-Ti, non-causal, DiT's fixed sin-cos pos_embed (a follow-up, not the paper's model)",
        )
    },
    Arm {
        pos_embed: PosEmbed::LearnedSinCos,
        ..scaledp(
            "ti-learned-sincos",
            ModelSize::Ti,
            Attention::NonCausal,
            "ScaleDP-Ti, non-causal, pos_embed learned from DiT's sin-cos table (a follow-up)",
        )
    },
    Arm {
        steps_factor: 3,
        ..scaledp(
            "ti-x3",
            ModelSize::Ti,
            Attention::NonCausal,
            "ScaleDP-Ti, non-causal (the paper's), three times the recipe's steps",
        )
    },
    Arm {
        steps_factor: 3,
        ..scaledp(
            "ti-causal-x3",
            ModelSize::Ti,
            Attention::Causal,
            "ScaleDP-Ti, causal attention, three times the recipe's steps",
        )
    },
    dpt(
        "dp-t",
        None,
        "DP-T, diffusion_policy's transformer (8 layers, width 256, 4 heads; the paper's baseline)",
    ),
    dpt("dp-t-l12", Some(12), "DP-T with 12 layers"),
    dpt("dp-t-l14", Some(14), "DP-T with 14 layers"),
];

/// The arm named `name`.
pub fn arm(name: &str) -> Option<Arm> {
    ARMS.iter().copied().find(|a| a.name == name)
}

/// The arms' names, for error messages.
pub fn names() -> String {
    ARMS.iter().map(|a| a.name).collect::<Vec<_>>().join(", ")
}
