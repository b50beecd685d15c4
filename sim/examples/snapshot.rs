//! Writes what every camera of a rig sees at a few moments of the scripted operator's episode,
//! as binary PPM files: `cargo run --release -p scaledp-sim --example snapshot -- RIG SEED DIR`.

use std::io::Write;
use std::sync::Arc;

use scaledp_schema::Rig;
use scaledp_sim::render::{render, View};
use scaledp_sim::{OfflineRun, Scene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let rig = Rig::load_or_builtin(&args.next().unwrap_or_else(|| "franka_sim".into()))?;
    let seed: u64 = args.next().map_or(Ok(0), |s| s.parse())?;
    let dir = std::path::PathBuf::from(args.next().unwrap_or_else(|| "snapshots".into()));
    std::fs::create_dir_all(&dir)?;
    let scene = Arc::new(Scene::new(&rig));
    let mut run = OfflineRun::new(scene.clone(), seed);
    for t in [0.0, 2.5, 3.8, 6.0, 8.0, 11.0] {
        run.advance_to((t * 1e9) as u64, &mut |_, _| {});
        let state = run.world().state();
        for (i, cam) in rig.cameras.iter().enumerate() {
            let view = View::for_camera(&scene, cam, i);
            let mut rgb = Vec::new();
            render(&scene, &view, &state, "rgb8", &mut rgb);
            let path = dir.join(format!("{}_{seed}_{t:04.1}_{}.ppm", rig.name, cam.name));
            let mut f = std::fs::File::create(&path)?;
            write!(f, "P6\n{} {}\n255\n", cam.width, cam.height)?;
            f.write_all(&rgb)?;
        }
    }
    println!("{}", dir.display());
    Ok(())
}
