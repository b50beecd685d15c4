//! `scaledp predict`: what a checkpoint does on a recorded episode — predicted vs recorded
//! action chunks (CSV) and the error per action dimension, before any robot moves.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use scaledp_policy::{predict_episode, Policy};

use crate::cli::ExitStatus;

/// `scaledp predict`.
#[derive(Debug, Args)]
pub struct PredictArgs {
    /// A checkpoint directory, or a run directory (its latest checkpoint).
    pub checkpoint: PathBuf,
    /// The dataset: a directory or s3://bucket/prefix.
    pub dataset: String,
    /// The episode's episode_index.
    #[arg(long, default_value_t = 0)]
    pub episode: i64,
    /// Write predicted vs recorded actions here (one row per frame and chunk step).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Windows per forward pass.
    #[arg(long, default_value_t = 16)]
    pub batch_size: usize,
    /// Seed of the sampling noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// cpu, or cuda (a build with the `cuda` feature of scaledp-policy).
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

/// Runs `scaledp predict`.
pub fn run(a: PredictArgs) -> Result<ExitStatus> {
    let dev = crate::shared::device(&a.device)?;
    let policy = Policy::load(&a.checkpoint, &dev)?;
    let p = predict_episode(&policy, &a.dataset, a.episode, a.batch_size, a.seed)?;
    let (c, dim) = (p.action_chunk, p.action_names.len());
    if let Some(path) = &a.out {
        let file = std::fs::File::create(path).with_context(|| path.display().to_string())?;
        let mut w = std::io::BufWriter::new(file);
        let mut head = vec![
            "episode".to_string(),
            "frame".into(),
            "step".into(),
            "padded".into(),
        ];
        head.extend(p.action_names.iter().map(|n| format!("predicted_{n}")));
        head.extend(p.action_names.iter().map(|n| format!("recorded_{n}")));
        writeln!(w, "{}", head.join(","))?;
        for (i, frame) in p.frames.iter().enumerate() {
            for k in 0..c {
                let row = (i * c + k) * dim;
                let mut cells = vec![
                    p.episode.to_string(),
                    frame.to_string(),
                    k.to_string(),
                    u8::from(p.is_pad[i * c + k]).to_string(),
                ];
                cells.extend(p.predicted[row..row + dim].iter().map(|v| v.to_string()));
                cells.extend(p.recorded[row..row + dim].iter().map(|v| v.to_string()));
                writeln!(w, "{}", cells.join(","))?;
            }
        }
        w.flush()?;
        eprintln!("wrote {}", path.display());
    }
    println!(
        "episode {}: {} frames, chunks of {c}, checkpoint {}",
        p.episode,
        p.frames.len(),
        policy.dir().display()
    );
    println!(
        "{:<24} {:>12} {:>12} {:>12}",
        "dimension", "MAE", "RMSE", "MAE first"
    );
    for d in 0..dim {
        println!(
            "{:<24} {:>12.5} {:>12.5} {:>12.5}",
            p.action_names[d], p.mae[d], p.rmse[d], p.mae_first[d]
        );
    }
    Ok(ExitStatus::Success)
}
