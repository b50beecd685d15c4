//! Training throughput and DDIM latency on this machine (what `scaledp bench train` reports):
//!
//! ```sh
//! cargo run --release -p scaledp-policy --example bench_train -- DATASET [WxH] [batch] [steps] [micro|-] [cam,cam]
//! ```
use candle_core::Device;
use scaledp_policy::bench::{ddim_latency, train_throughput};
use scaledp_policy::{ModelConfig, ModelSize, TrainOptions};

fn main() -> scaledp_policy::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let dataset = args
        .get(1)
        .cloned()
        .unwrap_or_else(|| "datasets/cups".into());
    let size = args.get(2).and_then(|s| {
        let (w, h) = s.split_once('x')?;
        Some((w.parse().ok()?, h.parse().ok()?))
    });
    let batch: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(64);
    let steps: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(3);
    let micro: Option<usize> = args.get(5).and_then(|s| s.parse().ok());
    let cams: Option<Vec<String>> = args
        .get(6)
        .map(|s| s.split(',').map(String::from).collect());
    let dev = Device::Cpu;
    let mut opts = TrainOptions::default()
        .model(ModelSize::Ti)
        .batch_size(batch)
        .val_ratio(0.0);
    if let Some((w, h)) = size {
        opts = opts.image_size(w, h);
    }
    if let Some(m) = micro {
        opts = opts.micro_batch(m);
    }
    if let Some(c) = &cams {
        opts = opts.cameras(c.clone());
    }
    let t = train_throughput(&dataset, opts, 1, steps, &dev)?;
    println!("train {dataset} {size:?} cameras {cams:?} batch {batch}: {:.2} s/step, {:.1} samples/s, data wait {:.1} %, params {:?}",
        t.step_s, t.samples_per_s, 100.0 * t.data_wait_share, t.params);
    for s in [ModelSize::Ti, ModelSize::S] {
        let cams = vec![
            "observation.images.front".into(),
            "observation.images.wrist".into(),
        ];
        let (w, h) = size.unwrap_or((320, 240));
        let cfg = ModelConfig::new(s, cams, (w, h), 7, 7);
        let l = ddim_latency(&cfg, 10, 20, &dev)?;
        println!(
            "ddim-10 {s} {w}x{h}: p50 {:.1} ms, p99 {:.1} ms",
            l.p50_ms, l.p99_ms
        );
    }
    Ok(())
}
