//! Saving a run's state into a checkpoint directory and resuming from one.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use candle_core::{Device, Tensor};
use scaledp_datasets::Loader;

use super::{open_loaders, optim::AdamW, TrainOptions, Trainer};
use crate::checkpoint::{self, CheckpointConfig, Normalization, NormalizerConfig};
use crate::config::{Architecture, DiffusionConfig, ModelConfig};
use crate::error::{Error, Result};
use crate::image_chain::{ImageChain, StoredImages, TrainResize};
use crate::model::params::Param;
use crate::model::ScaleDp;
use crate::scheduler::NoiseScheduler;

/// What a local dataset's `meta/info.json` says about where it came from (nothing for object
/// storage or when absent).
#[derive(Default)]
struct Provenance {
    robot_type: Option<String>,
    /// `scaledp.rig`.
    rig: Option<String>,
    /// `scaledp.action_space` (TCP poses when absent).
    action_space: scaledp_schema::ActionSpace,
    /// `scaledp.image_size` and `scaledp.jpeg_quality`: written by our converter.
    converted: Option<((u32, u32), Option<u8>)>,
    /// Each camera's stored (width, height) from its feature shape.
    stored: HashMap<String, (u32, u32)>,
}

fn provenance(dataset: &str) -> Provenance {
    let path = Path::new(dataset).join("meta/info.json");
    let Ok(bytes) = std::fs::read(path) else {
        return Provenance::default();
    };
    let Ok(v) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
        return Provenance::default();
    };
    let s = |x: Option<&serde_json::Value>| {
        x.and_then(|v| v.as_str())
            .filter(|s| !s.is_empty())
            .map(String::from)
    };
    let sd = v.get("scaledp");
    let size = sd
        .and_then(|x| x.get("image_size"))
        .and_then(|x| x.as_array())
        .and_then(|a| Some((a.first()?.as_u64()? as u32, a.get(1)?.as_u64()? as u32)));
    let quality = sd
        .and_then(|x| x.get("jpeg_quality"))
        .and_then(|x| x.as_u64())
        .map(|q| q as u8);
    let stored = v
        .get("features")
        .and_then(|f| f.as_object())
        .map(|f| {
            f.iter()
                .filter_map(|(k, f)| {
                    let f: scaledp_datasets::Feature = serde_json::from_value(f.clone()).ok()?;
                    Some((k.clone(), f.image_size()?))
                })
                .collect()
        })
        .unwrap_or_default();
    Provenance {
        robot_type: s(v.get("robot_type")),
        rig: s(sd.and_then(|x| x.get("rig"))),
        action_space: sd
            .and_then(|x| x.get("action_space"))
            .and_then(|x| serde_json::from_value(x.clone()).ok())
            .unwrap_or_default(),
        converted: size.map(|s| (s, quality)),
        stored,
    }
}

/// The image chain of a run on `dataset`'s cameras at the model's input size.
fn image_chain(p: &Provenance, model: &ModelConfig) -> ImageChain {
    let input = (model.image_width, model.image_height);
    let stored = model
        .cameras
        .first()
        .and_then(|c| p.stored.get(c).copied())
        .or(p.converted.map(|c| c.0))
        .unwrap_or(input);
    let (made_by, jpeg_quality) = match p.converted {
        Some((size, q)) if size == stored => ("scaledp-convert", q),
        _ => ("unknown", None),
    };
    ImageChain {
        stored: StoredImages {
            width: stored.0,
            height: stored.1,
            made_by: made_by.into(),
            jpeg_quality,
        },
        train_resize: (stored != input).then(|| TrainResize {
            width: input.0,
            height: input.1,
            filter: "bilinear".into(),
        }),
        crop: model.crop,
        range: model.image_range,
    }
}

/// The model and checkpoint configuration a run on `loader`'s data gets.
pub(super) fn config_for(
    dataset: &str,
    loader: &Loader,
    o: &TrainOptions,
) -> Result<CheckpointConfig> {
    let info = loader.info();
    let inputs = (
        info.cameras.clone(),
        (info.width, info.height),
        info.state_names.len(),
        info.action_names.len(),
    );
    let mut model = match o.arch {
        Architecture::ScaleDp => ModelConfig::new(o.size, inputs.0, inputs.1, inputs.2, inputs.3),
        Architecture::DpT => ModelConfig::dp_t(inputs.0, inputs.1, inputs.2, inputs.3),
    };
    if let Some(p) = o.dropout {
        model.dropout = p;
    }
    if let Some((depth, hidden, heads)) = o.denoiser {
        model.size = None;
        model.depth = depth;
        model.hidden = hidden;
        model.heads = heads;
    }
    model.obs_horizon = o.obs_horizon;
    model.action_chunk = o.action_chunk;
    model.crop = o.crop;
    model.resnet_width = o.resnet_width;
    model.image_range = o.image_range;
    model.attention = o.attention;
    model.pos_embed = o.pos_embed;
    model.validate()?;
    let prov = provenance(dataset);
    let images = (!model.cameras.is_empty()).then(|| image_chain(&prov, &model));
    let Provenance {
        robot_type,
        rig,
        action_space,
        ..
    } = prov;
    let n = loader.normalizer();
    Ok(CheckpointConfig {
        format: checkpoint::FORMAT.into(),
        version: checkpoint::VERSION,
        model,
        diffusion: DiffusionConfig::default(),
        normalizer: NormalizerConfig {
            state: Normalization::from_affine(&n.state),
            action: Normalization::from_affine(&n.action),
        },
        state_names: info.state_names.clone(),
        action_names: info.action_names.clone(),
        action_space,
        fps: info.fps,
        robot_type,
        rig,
        dataset: dataset.to_string(),
        step: 0,
        seed: o.seed,
        loader: None,
        train: serde_json::Value::Null,
        images,
    })
}

/// A second model whose weights are copies of `params` (the EMA starts at the weights).
pub(crate) fn copy_model(
    cfg: &ModelConfig,
    params: &[Param],
    device: &Device,
) -> Result<(ScaleDp, Vec<Param>)> {
    let tensors: HashMap<String, Tensor> = params
        .iter()
        .map(|p| Ok((p.name.clone(), p.var.as_tensor().copy()?)))
        .collect::<Result<_>>()?;
    ScaleDp::from_tensors(cfg, tensors, "(weights)", device)
}

/// Writes `out/checkpoints/step_N` (under a temporary name first).
pub(super) fn save(t: &mut Trainer) -> Result<PathBuf> {
    let root = t.out.join("checkpoints");
    let name = checkpoint::dir_name(t.step);
    let tmp = root.join(format!(".{name}.partial"));
    let dir = root.join(&name);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    let named = |ps: &[Param], prefix: &str| -> Vec<(String, Tensor)> {
        ps.iter()
            .map(|p| (format!("{prefix}{}", p.name), p.var.as_tensor().clone()))
            .collect()
    };
    checkpoint::write_tensors(&tmp.join(checkpoint::MODEL_FILE), named(&t.ema_params, ""))?;
    let mut state = named(t.optim.params(), "params.");
    for (n, v) in t.optim.state_tensors()? {
        state.push((format!("optim.{n}"), v));
    }
    checkpoint::write_tensors(&tmp.join(checkpoint::TRAIN_STATE_FILE), state)?;
    t.cfg.step = t.step;
    t.cfg.loader = Some(t.loader.state());
    t.cfg.train = serde_json::to_value(&t.opts).map_err(|e| Error::checkpoint(tmp.display(), e))?;
    t.cfg.write(&tmp)?;
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    }
    std::fs::rename(&tmp, &dir).map_err(|e| Error::io(&dir, e))?;
    Ok(dir)
}

/// Keeps the lines of `metrics.jsonl` up to `step` (a crash after the last checkpoint left
/// later ones), then opens it for appending.
fn reopen_metrics(run: &Path, step: u64) -> Result<std::fs::File> {
    let path = run.join("metrics.jsonl");
    let old = std::fs::read_to_string(&path).unwrap_or_default();
    let kept: String = old
        .lines()
        .filter(|l| {
            serde_json::from_str::<serde_json::Value>(l)
                .ok()
                .and_then(|v| v.get("record")?.get("step")?.as_u64())
                .is_some_and(|s| s <= step)
        })
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&path, kept).map_err(|e| Error::io(&path, e))?;
    std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .map_err(|e| Error::io(&path, e))
}

pub(super) fn resume(run: &Path, steps: Option<u64>, device: &Device) -> Result<Trainer> {
    let (step, dir) = checkpoint::list(run)?
        .pop()
        .ok_or_else(|| Error::checkpoint(run.display(), "no checkpoints/step_* to resume from"))?;
    let mut cfg = CheckpointConfig::read(&dir)?;
    let cfg_path = dir.join(checkpoint::CONFIG_FILE);
    let mut opts: TrainOptions = serde_json::from_value(cfg.train.clone())
        .map_err(|e| Error::checkpoint(cfg_path.display(), format!("train settings: {e}")))?;
    if let Some(s) = steps {
        opts.steps = s;
    }
    let (mut loader, val) = open_loaders(&cfg.dataset, &opts)?;
    let fresh = config_for(&cfg.dataset, &loader, &opts)?;
    if fresh.model != cfg.model || fresh.normalizer != cfg.normalizer {
        return Err(Error::checkpoint(
            cfg_path.display(),
            format!(
                "the dataset {} no longer matches the checkpoint's inputs or normalizer",
                cfg.dataset
            ),
        ));
    }
    if let Some(state) = cfg.loader {
        loader.resume(state)?;
    }
    let ts_path = dir.join(checkpoint::TRAIN_STATE_FILE);
    let mut ts = checkpoint::read_tensors(&ts_path, device)?;
    let mut raw = HashMap::new();
    let keys: Vec<String> = ts
        .keys()
        .filter(|k| k.starts_with("params."))
        .cloned()
        .collect();
    for k in keys {
        if let Some(v) = ts.remove(&k) {
            raw.insert(k["params.".len()..].to_string(), v);
        }
    }
    let optim_state: HashMap<String, Tensor> = ts
        .into_iter()
        .filter_map(|(k, v)| k.strip_prefix("optim.").map(|n| (n.to_string(), v)))
        .collect();
    let ts_name = ts_path.display().to_string();
    let (model, params) = ScaleDp::from_tensors(&cfg.model, raw, &ts_name, device)?;
    let model_path = dir.join(checkpoint::MODEL_FILE);
    let ema_t = checkpoint::read_tensors(&model_path, device)?;
    let (ema_model, ema_params) =
        ScaleDp::from_tensors(&cfg.model, ema_t, &model_path.display().to_string(), device)?;
    let mut optim = AdamW::new(params, opts.adamw)?;
    optim.load_state(&optim_state, step, &ts_name)?;
    cfg.step = step;
    let file = reopen_metrics(run, step)?;
    Ok(Trainer {
        scheduler: NoiseScheduler::new(cfg.diffusion.train_steps)?,
        opts,
        out: run.to_path_buf(),
        loader,
        val,
        cfg,
        model,
        ema_model,
        ema_params,
        optim,
        step,
        metrics: std::io::BufWriter::new(file),
        stop: Arc::new(AtomicBool::new(false)),
        last_checkpoint: Some(dir),
        engine: Default::default(),
    })
}
