//! `scaledp view PATH…`: recordings, bags and datasets in the rerun viewer (or an `.rrd` file);
//! and the live view of `scaledp record --view`.

use anyhow::Result;

use crate::cli::{ExitStatus, ViewArgs};

#[cfg(feature = "view")]
pub fn run(args: ViewArgs) -> Result<ExitStatus> {
    use scaledp_viewer::{Target, ViewOptions};
    let target = match (&args.save, &args.connect) {
        (Some(out), _) => Target::Save(out.clone()),
        (None, Some(url)) => Target::Connect(url.clone()),
        (None, None) => Target::Spawn,
    };
    let rig = args
        .rig
        .as_deref()
        .map(scaledp_schema::Rig::load_or_builtin)
        .transpose()?;
    let mut opts = ViewOptions::new()
        .max_width(args.max_width)
        .episodes(args.episode.clone())
        .rig(rig)
        .action_space(args.action_space)
        .chunk(args.chunk);
    if let Some(ckpt) = &args.checkpoint {
        for (episode, p) in predictions(ckpt, &args)? {
            opts = opts.prediction(episode, p);
        }
    }
    let summary = scaledp_viewer::view(&args.paths, opts, &target)?;
    for s in &summary.shown {
        let images: u64 = s.images.values().sum();
        println!(
            "{}\t{} frames\t{images} images\t{} cameras",
            s.name,
            s.frames,
            s.images.len()
        );
        for w in &s.warnings {
            eprintln!("{}: {w}", s.name);
        }
    }
    match (&summary.saved, &target) {
        (Some(out), _) => eprintln!(
            "wrote {} (open it with `rerun {}`)",
            out.display(),
            out.display()
        ),
        (None, Target::Connect(url)) => eprintln!("sent to the rerun viewer at {url}"),
        _ => eprintln!("sent to the rerun viewer"),
    }
    Ok(ExitStatus::Success)
}

/// The checkpoint's predicted chunks over each `--episode` of the one dataset given.
#[cfg(feature = "view")]
fn predictions(
    checkpoint: &std::path::Path,
    args: &ViewArgs,
) -> Result<Vec<(u64, scaledp_viewer::Prediction)>> {
    use anyhow::Context;
    let [dataset] = args.paths.as_slice() else {
        anyhow::bail!("--checkpoint: give exactly one LeRobot dataset");
    };
    if args.episode.is_empty() {
        anyhow::bail!(
            "--checkpoint: name the episodes to predict with --episode N (each costs a DDIM sample per frame)"
        );
    }
    let policy = scaledp_policy::Policy::load(checkpoint, &candle_core::Device::Cpu)?;
    let mut out = Vec::new();
    for &episode in &args.episode {
        eprintln!(
            "predicting episode {episode} with {}…",
            policy.dir().display()
        );
        let p = scaledp_policy::predict_episode(&policy, dataset, episode as i64, 16, 0)
            .with_context(|| format!("--checkpoint {}", checkpoint.display()))?;
        out.push((
            episode,
            scaledp_viewer::Prediction {
                frames: p.frames,
                values: p.predicted,
            },
        ));
    }
    Ok(out)
}

#[cfg(not(feature = "view"))]
pub fn run(_args: ViewArgs) -> Result<ExitStatus> {
    anyhow::bail!("this scaledp was built without the `view` feature (rerun)")
}
