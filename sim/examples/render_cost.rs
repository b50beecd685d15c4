//! Milliseconds per rendered frame for every camera of the shipped rigs, on one thread, over
//! the scripted operator's episode: `cargo run --release -p scaledp-sim --example render_cost`.

use std::sync::Arc;
use std::time::Instant;

use scaledp_schema::Rig;
use scaledp_sim::render::{render, View};
use scaledp_sim::{OfflineRun, Scene};

fn main() {
    for name in Rig::builtin_names() {
        let Some(rig) = Rig::builtin(name) else {
            continue;
        };
        let scene = Arc::new(Scene::new(&rig));
        for (i, cam) in rig.cameras.iter().enumerate() {
            let view = View::for_camera(&scene, cam, i);
            let mut run = OfflineRun::new(scene.clone(), 1);
            let (frames, mut busy, mut buf) = (60, 0.0, Vec::new());
            for k in 0..frames {
                // Every sixth of a second of the episode: rest, reach, grasp, carry, place.
                run.advance_to(k * 166_666_667, &mut |_, _| {});
                let state = run.world().state();
                let t = Instant::now();
                render(&scene, &view, &state, cam.encoding(), &mut buf);
                busy += t.elapsed().as_secs_f64();
            }
            let ms = busy * 1e3 / frames as f64;
            println!(
                "{name:<18} {:<12} {:>4}×{:<4} {:<6} {ms:6.2} ms/frame  ({:.0} % of a core at {} fps)",
                cam.name,
                cam.width,
                cam.height,
                cam.encoding(),
                ms * cam.fps / 10.0,
                cam.fps
            );
        }
    }
}
