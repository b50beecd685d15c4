//! The image chain: a camera frame reaches the policy as the same bytes in deployment as in
//! training. A rollout is recorded, converted at a size of its own (24×20, JPEG quality 85, not
//! the cameras' 80×45 nor their aspect), a tiny policy trained on it for one step with and
//! without `--image-size`, and the rollout replayed into a controller built from that
//! checkpoint: every window's images equal, byte for byte, what the training loader produced
//! for the same frames.
#![allow(clippy::unwrap_used)]

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use candle_core::Device;
use scaledp_converter::{read_mcap, ConvertOptions, JobOptions};
use scaledp_datasets::LoaderOptions;
use scaledp_deploy::{run_eval, ControlOptions, Controller, EvalOptions};
use scaledp_policy::{Policy, TrainOptions, Trainer};

/// One step of a tiny model on `ds` into `run` (images resized to `size` when given).
fn train(ds: &Path, run: &Path, size: Option<(u32, u32)>) -> Policy {
    let mut opts = TrainOptions::default()
        .denoiser(1, 16, 2)
        .resnet_width(4)
        .steps(1)
        .batch_size(4)
        .val_ratio(0.0)
        .val_every(0)
        .checkpoint_every(0)
        .action_chunk(16);
    if let Some((w, h)) = size {
        opts = opts.image_size(w, h);
    }
    let mut t = Trainer::new(ds.to_str().unwrap(), run, opts, &Device::Cpu).unwrap();
    t.run(|_| {}).unwrap();
    Policy::load(run, &Device::Cpu).unwrap()
}

#[test]
fn deployment_feeds_the_bytes_training_saw_with_and_without_image_size() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let at_home = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let opts = EvalOptions {
        episodes: 1,
        max_seconds: 2.5,
        recordings: Some(dir.path().join("rollouts")),
        ..EvalOptions::default()
    };
    let report = run_eval(&at_home, &rig, &opts, &mut |_| {}).unwrap();
    let mcap = std::path::PathBuf::from(report.episodes[0].recording.clone().unwrap());
    let ds = dir.path().join("ds");
    let job = JobOptions::default()
        .convert(
            ConvertOptions::default()
                .size(24, 20)
                .jpeg_quality(85)
                .rig(rig.clone()),
        )
        .include_failures(true);
    let results = scaledp_converter::run(std::slice::from_ref(&mcap), &ds, &job, &|_| {}).unwrap();
    assert!(
        results
            .iter()
            .all(|(_, r)| matches!(r, scaledp_converter::InputResult::Converted(..))),
        "{results:?}"
    );
    let rec = read_mcap(&mcap, &|_| true).unwrap();

    for (name, size) in [
        ("stored size", None),
        ("--image-size 16x12", Some((16u32, 12u32))),
    ] {
        let policy = train(
            &ds,
            &dir.path().join(format!("run-{}", size.is_some())),
            size,
        );
        let chain = policy.config().image_chain();
        assert_eq!(
            (chain.stored.width, chain.stored.height),
            (24, 20),
            "{name}"
        );
        assert_eq!(chain.stored.jpeg_quality, Some(85), "{name}");
        assert_eq!(chain.stored.made_by, "scaledp-convert", "{name}");
        assert_eq!(
            chain.train_resize.as_ref().map(|r| (r.width, r.height)),
            size,
            "{name}"
        );
        let (w, h) = size.unwrap_or((24, 20));

        // The training loader's windows, by frame.
        let mut lo = LoaderOptions::default()
            .obs_horizon(2)
            .action_chunk(16)
            .batch_size(1)
            .shuffle(false);
        if let Some((w, h)) = size {
            lo = lo.image_size(w, h);
        }
        let mut loader = lo.open(ds.to_str().unwrap()).unwrap();
        let mut trained: BTreeMap<i64, Vec<u8>> = BTreeMap::new();
        while let Some(b) = loader.next_batch() {
            let b = b.unwrap();
            trained.insert(b.frame_index[0], b.images.clone());
        }
        assert!(trained.len() >= 15, "{name}: {} frames", trained.len());

        // The controller's windows for the same ticks.
        let ctl_opts = ControlOptions {
            action_steps: 1,
            obs_lag_s: 0.0,
            ..ControlOptions::default()
        };
        let mut ctl = Controller::new(policy.config(), "trained", &rig, ctl_opts).unwrap();
        let windows = common::replay(&mut ctl, &rig, &rec, 30);
        let per = 2 * 2 * 3 * (w * h) as usize;
        let mut compared = 0;
        for (k, obs) in &windows {
            // Tick 0's window is padded differently (the loader repeats frame 0).
            let Some(want) = trained.get(&(*k as i64)).filter(|_| *k > 0) else {
                continue;
            };
            assert_eq!(obs.images.len(), per, "{name}");
            assert!(
                obs.images == *want,
                "{name}: tick {k}: the controller's images differ from the loader's"
            );
            compared += 1;
        }
        assert!(compared >= 12, "{name}: {compared} windows compared");
    }
}
