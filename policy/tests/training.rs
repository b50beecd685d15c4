//! Training runs on tiny datasets: exact resume, checkpoint round trips, overfitting one
//! episode, and the errors bad inputs give.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] functions

use crate::common;

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use scaledp_policy::model::Crop;
use scaledp_policy::{predict_episode, Event, Observation, Policy, PosEmbed, Trainer};

fn losses(t: &mut Trainer, n: usize) -> Vec<f32> {
    (0..n).map(|_| t.step().map(|r| r.loss).unwrap()).collect()
}

#[test]
fn a_resumed_run_takes_the_same_steps_as_an_uninterrupted_one() {
    let ds = common::write(&common::Fixture::default());
    let dev = Device::Cpu;
    let opts = common::tiny().steps(7).grad_clip(1.0);
    let out = tempfile::tempdir().unwrap();
    let mut a = Trainer::new(&ds.location(), &out.path().join("a"), opts.clone(), &dev).unwrap();
    let straight = losses(&mut a, 7);
    let mut b = Trainer::new(&ds.location(), &out.path().join("b"), opts, &dev).unwrap();
    let first = losses(&mut b, 3);
    b.save_checkpoint().unwrap();
    drop(b);
    let mut c = Trainer::resume(&out.path().join("b"), None, &dev).unwrap();
    assert_eq!(c.step_count(), 3);
    let rest = losses(&mut c, 4);
    assert_eq!(&straight[..3], &first[..]);
    // Bit for bit: same data order, optimizer state, EMA and random stream.
    assert_eq!(&straight[3..], &rest[..], "resumed losses differ");
    assert!(straight.iter().all(|l| l.is_finite() && *l > 0.0));
    // metrics.jsonl has one train line per step.
    let lines = std::fs::read_to_string(out.path().join("b/metrics.jsonl")).unwrap();
    assert_eq!(lines.lines().filter(|l| l.contains("\"train\"")).count(), 7);
}

#[test]
fn a_checkpoint_loads_back_to_bit_identical_outputs() {
    let ds = common::write(&common::Fixture::default());
    let dev = Device::Cpu;
    let out = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(&ds.location(), out.path(), common::tiny().steps(3), &dev).unwrap();
    let mut events = Vec::new();
    let summary = t.run(|e| events.push(e.clone())).unwrap();
    assert_eq!(summary.steps, 3);
    assert!(matches!(events.last(), Some(Event::Checkpoint(_))));
    let dir = summary.checkpoint.unwrap();
    for f in [
        "model.safetensors",
        "train_state.safetensors",
        "config.json",
    ] {
        assert!(dir.join(f).exists(), "{f}");
    }
    let policy = Policy::load(out.path(), &dev).unwrap();
    assert_eq!(policy.dir(), dir.as_path());
    let cfg = policy.config();
    assert_eq!(cfg.robot_type.as_deref(), Some("test_arm"));
    // The anchors' defaults: state and actions min-max to [-1, 1], images in [-1, 1],
    // padded actions trained on, the encoders decayed at 1e-6.
    assert_eq!(cfg.normalizer.state.norm, "min_max");
    assert_eq!(cfg.normalizer.action.norm, "min_max");
    assert_eq!(cfg.model.image_range, scaledp_policy::ImageRange::Symmetric);
    assert_eq!(cfg.train["loss"]["mask_padding"], false);
    assert_eq!(cfg.train["adamw"]["encoder_weight_decay"], 1e-6);
    assert_eq!(cfg.train["adamw"]["weight_decay"], 1e-3);
    assert_eq!(cfg.rig.as_deref(), Some("test_rig"));
    assert_eq!(
        cfg.model.cameras,
        vec!["observation.images.front", "observation.images.wrist"]
    );
    // Same inputs through the in-memory EMA model and the loaded one.
    let m = &cfg.model;
    let n_img = 2 * m.obs_horizon * 2 * 3 * 20 * 16;
    let images: Vec<u8> = (0..n_img).map(|i| (i * 31 % 256) as u8).collect();
    let state = vec![0.2f32; 2 * m.obs_horizon * 3];
    let run = |model: &scaledp_policy::model::ScaleDp| {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let cond = model
            .encode(&images, &state, 2, Crop::Random, &mut rng)
            .unwrap();
        let x = Tensor::ones((2, m.action_chunk, 2), candle_core::DType::F32, &dev).unwrap();
        let eps = model.predict_noise(&x, &[3.0, 50.0], &cond).unwrap();
        eps.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    };
    let (mem, loaded) = (run(t.ema_model()), run(policy.model()));
    assert!(
        mem.iter().any(|v| *v != 0.0),
        "the trained model outputs something"
    );
    assert_eq!(mem, loaded);
    // predict is deterministic for a seed, and gives raw-unit chunks of [C, A].
    let obs = Observation {
        images: images[..n_img / 2].to_vec(),
        state: vec![0.1; m.obs_horizon * 3],
    };
    let (p1, p2) = (
        policy.predict(&obs, 4).unwrap(),
        policy.predict(&obs, 4).unwrap(),
    );
    assert_eq!(p1, p2);
    assert_eq!(
        (p1.chunk, p1.dim, p1.actions.len()),
        (m.action_chunk, 2, m.action_chunk * 2)
    );
}

/// One short episode, learnt: the loss falls 10× and DDIM samples give back its actions.
#[test]
fn overfitting_one_episode_reproduces_its_actions() {
    let fx = common::Fixture {
        lens: vec![10],
        cameras: vec!["front".into()],
        size: (16, 12),
        ..Default::default()
    };
    let ds = common::write(&fx);
    let dev = Device::Cpu;
    let out = tempfile::tempdir().unwrap();
    let opts = common::tiny()
        .denoiser(2, 64, 4)
        .batch_size(10)
        .steps(600)
        .warmup_steps(20)
        .lr(2e-3)
        .crop(1.0);
    let mut t = Trainer::new(&ds.location(), out.path(), opts, &dev).unwrap();
    let mut l = Vec::new();
    let summary = t
        .run(|e| {
            if let Event::Step(r) = e {
                l.push(r.loss)
            }
        })
        .unwrap();
    let first: f32 = l[..10].iter().sum::<f32>() / 10.0;
    let last: f32 = l[l.len() - 20..].iter().sum::<f32>() / 20.0;
    assert!(last * 10.0 <= first, "loss {first} → {last}");
    let policy = Policy::load(&summary.checkpoint.unwrap(), &dev).unwrap();
    let p = predict_episode(&policy, &ds.location(), 0, 16, 0).unwrap();
    assert_eq!(p.frames, (0..10).collect::<Vec<i64>>());
    let norm = &policy.config().normalizer.action;
    let (mut pred, mut rec) = (p.predicted.clone(), p.recorded.clone());
    norm.apply(&mut pred);
    norm.apply(&mut rec);
    let mut errs: Vec<f32> = Vec::new();
    for (k, pad) in p.is_pad.iter().enumerate() {
        if !pad {
            errs.extend((0..2).map(|d| (pred[k * 2 + d] - rec[k * 2 + d]).abs()));
        }
    }
    errs.sort_by(f32::total_cmp);
    let mean = errs.iter().sum::<f32>() / errs.len() as f32;
    let p90 = errs[errs.len() * 9 / 10];
    // Every recorded step of every chunk: on average well within 0.1, nine in ten within 0.1.
    assert!(
        mean <= 0.05 && p90 <= 0.1,
        "normalized error: mean {mean}, 90th percentile {p90}, max {:?} (loss {first} → {last})",
        errs.last()
    );
}

#[test]
fn a_nan_in_a_batch_refuses_the_step_naming_the_sample() {
    let fx = common::Fixture {
        lens: vec![6],
        nan_at: Some((0, 3)),
        ..Default::default()
    };
    let ds = common::write(&fx);
    let out = tempfile::tempdir().unwrap();
    let opts = common::tiny().batch_size(6);
    let mut t = Trainer::new(&ds.location(), out.path(), opts, &Device::Cpu).unwrap();
    let e = t.step().unwrap_err().to_string();
    assert!(
        e.contains("non-finite state") && e.contains("episode 0 frame"),
        "{e}"
    );
}

#[test]
fn mismatched_missing_and_foreign_checkpoints_are_named() {
    let ds = common::write(&common::Fixture::default());
    let dev = Device::Cpu;
    let out = tempfile::tempdir().unwrap();
    let mut t = Trainer::new(&ds.location(), out.path(), common::tiny().steps(1), &dev).unwrap();
    let dir = t.run(|_| {}).unwrap().checkpoint.unwrap();
    let policy = Policy::load(&dir, &dev).unwrap();
    // A dataset with other cameras.
    let other = common::write(&common::Fixture {
        cameras: vec!["left".into()],
        ..Default::default()
    });
    let e = predict_episode(&policy, &other.location(), 0, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cameras mismatch") && e.contains("observation.images.front"),
        "{e}"
    );
    // A dataset with another state width.
    let other = common::write(&common::Fixture {
        state_dim: 5,
        ..Default::default()
    });
    let e = predict_episode(&policy, &other.location(), 0, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("state dimension mismatch"), "{e}");
    // An episode the dataset does not have.
    let e = predict_episode(&policy, &ds.location(), 42, 4, 0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no episode 42"), "{e}");
    // An observation of the wrong size.
    let e = policy
        .predict(&Observation::default(), 0)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("image bytes") && e.contains("observation.images.front"),
        "{e}"
    );
    // A missing weights file.
    let broken = out.path().join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::copy(dir.join("config.json"), broken.join("config.json")).unwrap();
    let e = Policy::load(&broken, &dev).unwrap_err().to_string();
    assert!(e.contains("model.safetensors"), "{e}");
    // A config.json of another version.
    let text = std::fs::read_to_string(dir.join("config.json")).unwrap();
    std::fs::write(
        broken.join("config.json"),
        text.replace("\"version\": 1", "\"version\": 7"),
    )
    .unwrap();
    let e = Policy::load(&broken, &dev).unwrap_err().to_string();
    assert!(
        e.contains("config.json") && e.contains("version Some(7)"),
        "{e}"
    );
    // Nothing there at all.
    let e = Policy::load(&out.path().join("nope"), &dev)
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope"), "{e}");
    // A new run where checkpoints already are.
    let e = Trainer::new(&ds.location(), out.path(), common::tiny(), &dev)
        .unwrap_err()
        .to_string();
    assert!(e.contains("already holds checkpoints"), "{e}");
}

/// `pos_embed: sin-cos`: DiT's table from the start, left bit for bit as it is by training
/// (optimizer and EMA) while the learned weights move, and recorded in the checkpoint.
#[test]
fn a_sin_cos_pos_embed_stays_fixed_while_the_rest_trains() {
    let ds = common::write(&common::Fixture::default());
    let dev = Device::Cpu;
    let out = tempfile::tempdir().unwrap();
    // 5 steps: the zero-initialised adaLN layers give `pos_embed` no gradient for the first two.
    let opts = common::tiny().steps(5).pos_embed(PosEmbed::SinCos);
    let mut t = Trainer::new(&ds.location(), out.path(), opts, &dev).unwrap();
    let start = t.save_checkpoint().unwrap();
    let end = t.run(|_| {}).unwrap().checkpoint.unwrap();
    // `model.safetensors` holds the EMA weights, `train_state.safetensors` the trained ones.
    let read = |dir: &std::path::Path, file: &str, name: &str| {
        let w = candle_core::safetensors::load(dir.join(file), &dev).unwrap();
        w[name].flatten_all().unwrap().to_vec1::<f32>().unwrap()
    };
    let weights = |dir: &std::path::Path, name: &str| read(dir, "model.safetensors", name);
    let pos = weights(&end, "pos_embed");
    assert_eq!(
        read(&end, "train_state.safetensors", "params.pos_embed"),
        pos,
        "the optimizer moved the table"
    );
    // Width 32, chunk 4: row p is [sin(p·ω_i), cos(p·ω_i)], ω_i = 10000^(−i/16), i < 16.
    assert_eq!(pos.len(), 4 * 32);
    for p in 0..4 {
        for i in 0..16 {
            let a = p as f64 * 10000f64.powf(-(i as f64) / 16.0);
            assert_eq!(pos[p * 32 + i], a.sin() as f32, "row {p}, sin {i}");
            assert_eq!(pos[p * 32 + 16 + i], a.cos() as f32, "row {p}, cos {i}");
        }
    }
    assert_eq!(weights(&start, "pos_embed"), pos);
    assert_ne!(
        weights(&start, "x_embedder.weight"),
        weights(&end, "x_embedder.weight"),
        "the learned weights train"
    );
    let policy = Policy::load(out.path(), &dev).unwrap();
    assert_eq!(policy.config().model.pos_embed, PosEmbed::SinCos);
}

/// `pos_embed: learned-sin-cos`: DiT's table at step 0, then trained with the other weights
/// (the optimizer moves it), and recorded in the checkpoint.
#[test]
fn a_learned_sin_cos_pos_embed_starts_at_the_table_and_trains() {
    let ds = common::write(&common::Fixture::default());
    let dev = Device::Cpu;
    let out = tempfile::tempdir().unwrap();
    let opts = common::tiny().steps(5).pos_embed(PosEmbed::LearnedSinCos);
    let mut t = Trainer::new(&ds.location(), out.path(), opts, &dev).unwrap();
    let start = t.save_checkpoint().unwrap();
    let end = t.run(|_| {}).unwrap().checkpoint.unwrap();
    let read = |dir: &std::path::Path, file: &str, name: &str| {
        let w = candle_core::safetensors::load(dir.join(file), &dev).unwrap();
        w[name].flatten_all().unwrap().to_vec1::<f32>().unwrap()
    };
    let first = read(&start, "model.safetensors", "pos_embed");
    // Width 32, chunk 4: the same table as the fixed embedding's at step 0.
    for p in 0..4 {
        for i in 0..16 {
            let a = p as f64 * 10000f64.powf(-(i as f64) / 16.0);
            assert_eq!(first[p * 32 + i], a.sin() as f32, "row {p}, sin {i}");
            assert_eq!(first[p * 32 + 16 + i], a.cos() as f32, "row {p}, cos {i}");
        }
    }
    let trained = read(&end, "train_state.safetensors", "params.pos_embed");
    assert_ne!(
        trained, first,
        "the optimizer left the table where it started"
    );
    let policy = Policy::load(out.path(), &dev).unwrap();
    assert_eq!(policy.config().model.pos_embed, PosEmbed::LearnedSinCos);
}
