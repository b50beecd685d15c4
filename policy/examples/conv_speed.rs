//! Times one forward + backward of a ResNet-18-GN encoder on the CPU.
use std::time::Instant;

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use scaledp_policy::model::{Crop, ScaleDp};
use scaledp_policy::{ModelConfig, ModelSize};

fn main() -> scaledp_policy::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let side: u32 = args.get(1).map_or(84, |s| s.parse().unwrap_or(84));
    let b: usize = args.get(2).map_or(64, |s| s.parse().unwrap_or(64));
    let cams: usize = args.get(3).map_or(1, |s| s.parse().unwrap_or(1));
    let cameras = (0..cams).map(|i| format!("observation.images.c{i}")).collect();
    let cfg = ModelConfig::new(ModelSize::Ti, cameras, (side, side), 14, 14);
    let dev = Device::Cpu;
    let (model, params) = scaledp_policy::model::ScaleDp::fresh_for_bench(&cfg, 0, &dev)?;
    let images = vec![100u8; b * 2 * cams * 3 * (side * side) as usize];
    let state = vec![0.1f32; b * 2 * 14];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    for it in 0..3 {
        let t0 = Instant::now();
        let cond = model.encode(&images, &state, b, Crop::Random, &mut rng)?;
        let x = Tensor::randn(0f32, 1., (b, 16, 14), &dev)?;
        let t = vec![10f32; b];
        let eps = model.predict_noise(&x, &t, &cond)?;
        let loss = ((eps - &x)?.sqr()?.mean_all()? + cond.sqr()?.mean_all()?)?;
        let t1 = Instant::now();
        let grads = loss.backward()?;
        let t2 = Instant::now();
        let mut n = 0;
        for p in &params {
            if grads.get(p.var.as_tensor()).is_some() { n += 1; }
        }
        println!("iter {it}: forward {:.2}s backward {:.2}s ({n}/{} grads)", (t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64(), params.len());
        let _ = ScaleDp::count(&cfg)?;
    }
    Ok(())
}
