//! What a checkpoint does on a recorded episode, before any robot moves: every frame t of the
//! episode as an observation window (as the loader builds it for training), the predicted
//! chunk beside the recorded one, and the error per action dimension.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use scaledp_datasets::{LoaderOptions, LoaderState, Norm, Split};

use crate::error::{Error, Result};
use crate::inference::Policy;

/// Predicted vs recorded actions over one episode, in raw units.
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodePrediction {
    /// The episode's `episode_index`.
    pub episode: i64,
    /// Current frame t of each window.
    pub frames: Vec<i64>,
    /// C.
    pub action_chunk: usize,
    /// Names of the A action dimensions.
    pub action_names: Vec<String>,
    /// `[frames, C, A]`: the policy's chunk at each frame.
    pub predicted: Vec<f32>,
    /// `[frames, C, A]`: the recorded actions t … t+C−1 (the last one repeated past the end).
    pub recorded: Vec<f32>,
    /// `[frames, C]`: recorded steps past the episode's end (left out of the errors).
    pub is_pad: Vec<bool>,
    /// Mean absolute error per dimension over every non-padded step of every chunk.
    pub mae: Vec<f64>,
    /// Root mean squared error per dimension, likewise.
    pub rmse: Vec<f64>,
    /// Mean absolute error per dimension of the first action of each chunk only (the one a
    /// robot executes first).
    pub mae_first: Vec<f64>,
}

/// Runs `policy` over episode `episode` (its `episode_index`) of `dataset`, `batch_size`
/// windows at a time, with sampling noise seeded by `seed`.
pub fn predict_episode(
    policy: &Policy,
    dataset: &str,
    episode: i64,
    batch_size: usize,
    seed: u64,
) -> Result<EpisodePrediction> {
    let cfg = policy.config();
    let m = &cfg.model;
    let ckpt = policy.dir().display().to_string();
    // Raw values from the loader; the checkpoint's own normalizer is applied here.
    let base = || {
        LoaderOptions::default()
            .obs_horizon(m.obs_horizon)
            .action_chunk(m.action_chunk)
            .split(Split::All)
            .shuffle(false)
            .batch_size(batch_size.max(1))
            .state_norm(Norm::None)
            .action_norm(Norm::None)
    };
    let mut loader = match base()
        .cameras(m.cameras.clone())
        .image_size(m.image_width, m.image_height)
        .open(dataset)
    {
        Ok(l) => l,
        Err(e) => {
            // Say which cameras differ when that is why.
            if let Ok(l) = base().open(dataset) {
                let have = &l.info().cameras;
                if m.cameras.iter().any(|c| !have.contains(c)) {
                    return Err(mismatch("cameras", &ckpt, &m.cameras, dataset, have));
                }
            }
            return Err(e.into());
        }
    };
    let info = loader.info().clone();
    if info.state_names.len() != m.state_dim {
        return Err(mismatch(
            "state dimension",
            &ckpt,
            &cfg.state_names,
            dataset,
            &info.state_names,
        ));
    }
    if info.action_names.len() != m.action_dim {
        return Err(mismatch(
            "action dimension",
            &ckpt,
            &cfg.action_names,
            dataset,
            &info.action_names,
        ));
    }
    let pos = info
        .episodes
        .iter()
        .position(|&e| e == episode)
        .ok_or_else(|| {
            Error::Config(format!(
                "{dataset}: no episode {episode} (it has {} episodes: {}..={})",
                info.episodes.len(),
                info.episodes.first().copied().unwrap_or(0),
                info.episodes.last().copied().unwrap_or(-1)
            ))
        })?;
    let start: usize = info.episode_lengths[..pos].iter().sum();
    let len = info.episode_lengths[pos];
    loader.resume(LoaderState {
        epoch: 0,
        position: start as u64,
    })?;
    let (ch, a) = (m.action_chunk, m.action_dim);
    let mut out = EpisodePrediction {
        episode,
        frames: Vec::with_capacity(len),
        action_chunk: ch,
        action_names: cfg.action_names.clone(),
        predicted: Vec::with_capacity(len * ch * a),
        recorded: Vec::with_capacity(len * ch * a),
        is_pad: Vec::with_capacity(len * ch),
        mae: vec![0.0; a],
        rmse: vec![0.0; a],
        mae_first: vec![0.0; a],
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    while out.frames.len() < len {
        let Some(batch) = loader.next_batch() else {
            break;
        };
        let mut batch = batch?;
        let keep = batch
            .episode_index
            .iter()
            .take_while(|&&e| e == episode)
            .count()
            .min(len - out.frames.len());
        let mut state = batch.state.clone();
        cfg.normalizer.state.apply(&mut state);
        let per_img = batch.images.len() / batch.len.max(1);
        let b = batch.len;
        let pred = policy.sample_normalized(&batch.images, &state, b, &mut rng)?;
        let mut pred = pred.flatten_all()?.to_vec1::<f32>()?;
        cfg.normalizer.action.invert(&mut pred);
        out.frames.extend_from_slice(&batch.frame_index[..keep]);
        out.predicted.extend_from_slice(&pred[..keep * ch * a]);
        out.recorded
            .extend_from_slice(&batch.action[..keep * ch * a]);
        out.is_pad
            .extend_from_slice(&batch.action_is_pad[..keep * ch]);
        let _ = per_img;
        batch.len = keep;
        loader.recycle(batch);
    }
    let (mut n, mut n_first) = (0usize, 0usize);
    for (k, &pad) in out.is_pad.iter().enumerate() {
        if pad {
            continue;
        }
        n += 1;
        let first = k % ch == 0;
        n_first += usize::from(first);
        for d in 0..a {
            let e = f64::from(out.predicted[k * a + d] - out.recorded[k * a + d]);
            out.mae[d] += e.abs();
            out.rmse[d] += e * e;
            if first {
                out.mae_first[d] += e.abs();
            }
        }
    }
    for d in 0..a {
        out.mae[d] /= n.max(1) as f64;
        out.rmse[d] = (out.rmse[d] / n.max(1) as f64).sqrt();
        out.mae_first[d] /= n_first.max(1) as f64;
    }
    Ok(out)
}

fn mismatch(what: &str, ckpt: &str, expected: &[String], dataset: &str, found: &[String]) -> Error {
    Error::Mismatch(Box::new(crate::error::Mismatch {
        what: what.into(),
        checkpoint: ckpt.into(),
        expected: format!("{} {expected:?}", expected.len()),
        other: format!("dataset {dataset}"),
        found: format!("{} {found:?}", found.len()),
    }))
}
