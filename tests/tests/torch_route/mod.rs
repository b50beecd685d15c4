//! The PyTorch route (`scaledp_data.policy`, `python -m scaledp_data.train` under `torchrun`)
//! against the Rust policy: one-step parity of loss and gradients, DDP over gloo on loopback
//! (2 ranks equal 1 process; disjoint shares; kill and resume), checkpoints moving between the
//! trainers and into `scaledp eval`, and the launch recipes' syntax.
//!
//! Needs torch: the one LeRobot brings into `.venv-bench` (`scripts/setup-bench-python.sh`,
//! torch 2.10.0; one copy of torch's gigabytes serves the video and the PyTorch tests), and the wheel
//! (`scripts/build-python.sh`), unpacked onto `PYTHONPATH`. Every run is a tiny model (2 blocks
//! of width 32, ResNet width 8) on a small simulated dataset, and every child is bounded in time.
#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

mod ddp;
mod dpt;
mod interop;
mod parity;
mod pos_embed;
mod recipes;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use scaledp_tests::{synth_episode, workspace, write_rig_file};

use crate::convert_common::convert_ok;

/// The Python with torch ([`scaledp_testkit::BENCH_VENV`]).
pub fn python() -> PathBuf {
    scaledp_testkit::BENCH_VENV
        .python(None, Some(&workspace()))
        .unwrap_or_else(|e| panic!("{e} (scripts/test.sh does)"))
}

/// The light simulated Franka cell: 80×45 cameras (non-square crops: 72×41), a 250 Hz arm.
pub fn light_rig() -> scaledp_schema::Rig {
    let mut rig = scaledp_schema::Rig::builtin("franka_sim")
        .unwrap()
        .with_image_size(80, 45);
    rig.arms[0].rate_hz = 250.0;
    rig
}

/// What every test shares: a converted dataset, the rig file and the unpacked wheel, in
/// `target/tmp/torch_route` (made afresh by each run of this binary, kept afterwards for a look
/// at what a failed test left).
pub struct Fixture {
    /// Holds everything below.
    pub dir: PathBuf,
    /// Four short episodes of [`light_rig`], converted.
    pub dataset: PathBuf,
    /// The rig as a file (for `scaledp eval --rig`).
    pub rig_file: PathBuf,
    /// Where `scaledp_data` imports from.
    pub site: PathBuf,
}

/// Made once per test binary.
pub fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("torch_route");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let rig = light_rig();
        let bags = dir.join("bags");
        std::fs::create_dir_all(&bags).unwrap();
        for (seed, seconds) in [(1u64, 2.4), (2, 3.0), (3, 2.0), (4, 2.7)] {
            synth_episode(
                &bags.join(format!("episode_{seed:06}.mcap")),
                &rig,
                seed,
                seconds,
            );
        }
        let rig_file = write_rig_file(&dir, &rig);
        let dataset = dir.join("ds");
        convert_ok(
            &[
                bags.as_os_str(),
                "--rig".as_ref(),
                rig_file.as_os_str(),
                "--size".as_ref(),
                "80x45".as_ref(),
                "--out".as_ref(),
                dataset.as_os_str(),
            ],
            "converted",
        );
        // SCALEDP_TORCH_SITE: a directory holding `scaledp_data` to test instead of the wheel
        // (working on the Python sources without rebuilding the wheel each time).
        let site = match std::env::var_os("SCALEDP_TORCH_SITE") {
            Some(s) if !s.is_empty() => PathBuf::from(s),
            _ => {
                let site = dir.join("site");
                unpack_wheel(&site);
                site
            }
        };
        Fixture {
            dir,
            dataset,
            rig_file,
            site,
        }
    })
}

/// The newest wheel, checked to be newer than the module's sources, unpacked into `site`.
fn unpack_wheel(site: &Path) {
    let wheel = scaledp_testkit::scaledp_data_wheel(None, Some(&workspace()))
        .unwrap_or_else(|e| panic!("{e} (scripts/test.sh does)"));
    let built = std::fs::metadata(&wheel).unwrap().modified().unwrap();
    let src = workspace().join("python/python/scaledp_data");
    for dir in [src.clone(), src.join("policy")] {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            assert!(
                std::fs::metadata(&p).unwrap().modified().unwrap() <= built,
                "{} is newer than {}: run scripts/build-python.sh",
                p.display(),
                wheel.display()
            );
        }
    }
    let out = Command::new(python())
        .args(["-m", "zipfile", "-e"])
        .arg(&wheel)
        .arg(site)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The tests' Python with the wheel on its path, gloo on loopback, one thread per process.
pub fn py() -> Command {
    let mut cmd = Command::new(python());
    cmd.env("PYTHONPATH", &fixture().site)
        .env("GLOO_SOCKET_IFNAME", "lo")
        .env("OMP_NUM_THREADS", "1")
        // Bytecode cached under target/, never beside the wheel's or the venv's sources: each of
        // these processes imports torch, and compiling its modules again in every one of them
        // cost these tests 25 s of their 82 s of CPU (58 s of wall time, now 43).
        .env_remove("PYTHONDONTWRITEBYTECODE")
        .env("PYTHONPYCACHEPREFIX", workspace().join("target/pycache"))
        .env("PYTHONFAULTHANDLER", "1")
        .stdin(Stdio::null());
    cmd
}

/// `python -m torch.distributed.run` (torchrun) with `ranks` processes on 127.0.0.1 at a free
/// port, running `python -m scaledp_data.train ARGS`; 1 rank runs the module without torchrun.
pub fn train_cmd(ranks: usize, args: &[&str]) -> Command {
    let mut cmd = py();
    if ranks > 1 {
        let port = scaledp_testkit::free_port().unwrap().to_string();
        cmd.args([
            "-m",
            "torch.distributed.run",
            "--nnodes",
            "1",
            "--nproc-per-node",
        ])
        .arg(ranks.to_string())
        .args(["--master-addr", "127.0.0.1", "--master-port", &port]);
    }
    cmd.args(["-m", "scaledp_data.train"]).args(args);
    cmd
}

/// The flags of the tiny model every training test uses.
pub const TINY: &[&str] = &[
    "--denoiser",
    "2,32,4",
    "--resnet-width",
    "8",
    "--batch-size",
    "8",
    "--warmup-steps",
    "2",
    "--val-every",
    "0",
    "--val-ratio",
    "0",
    "--device",
    "cpu",
];

/// Runs `cmd` (in its own process group) to its end or `limit`, then kills its tree; panics
/// unless it succeeded.
pub fn run_ok(mut cmd: Command, limit: Duration) -> Output {
    let out = run_bounded(&mut cmd, limit);
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}): {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs `cmd` in its own process group, bounded by `limit`.
pub fn run_bounded(cmd: &mut Command, limit: Duration) -> Output {
    use std::os::unix::process::CommandExt;
    let child = cmd
        .process_group(0)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = done.clone();
    let watchdog = std::thread::spawn(move || {
        let t0 = Instant::now();
        while t0.elapsed() < limit {
            if flag.load(std::sync::atomic::Ordering::Relaxed) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        kill_tree(pid);
        true
    });
    let out = child.wait_with_output().unwrap();
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    assert!(
        !watchdog.join().unwrap(),
        "{cmd:?} ran longer than {limit:?}"
    );
    out
}

/// SIGKILL to `pid`, its process group and every descendant (torchrun starts each worker in a
/// session of its own, so killing torchrun's group alone leaves the workers running).
pub fn kill_tree(pid: u32) {
    let mut parents: Vec<(u32, u32)> = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(p) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let stat = std::fs::read_to_string(e.path().join("stat")).unwrap_or_default();
        // Fields after the command name (in parentheses): state, ppid, ...
        let ppid = stat
            .rfind(')')
            .and_then(|i| stat[i + 2..].split_whitespace().nth(1)?.parse().ok());
        if let Some(pp) = ppid {
            parents.push((p, pp));
        }
    }
    let mut tree = vec![pid];
    let mut i = 0;
    while i < tree.len() {
        let p = tree[i];
        tree.extend(parents.iter().filter(|(_, pp)| *pp == p).map(|(c, _)| *c));
        i += 1;
    }
    let mut args = vec!["-KILL".to_string(), "--".into(), format!("-{pid}")];
    args.extend(tree.iter().map(u32::to_string));
    let _ = Command::new("kill").args(&args).status();
}

/// Spawns `cmd` in its own process group (the caller kills or waits).
pub fn spawn_group(cmd: &mut Command) -> Child {
    use std::os::unix::process::CommandExt;
    cmd.process_group(0)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The safetensors file's tensors as f32 vectors by name.
pub fn tensors(path: &Path) -> std::collections::BTreeMap<String, Vec<f32>> {
    let map = candle_core::safetensors::load(path, &candle_core::Device::Cpu).unwrap();
    map.into_iter()
        .map(|(k, t)| (k, t.flatten_all().unwrap().to_vec1::<f32>().unwrap()))
        .collect()
}

/// The largest |a − b| over every tensor the two files share (they must hold the same names).
pub fn max_weight_diff(a: &Path, b: &Path) -> f32 {
    let (ta, tb) = (tensors(a), tensors(b));
    assert_eq!(
        ta.keys().collect::<Vec<_>>(),
        tb.keys().collect::<Vec<_>>(),
        "{} and {} hold different tensors",
        a.display(),
        b.display()
    );
    ta.iter()
        .flat_map(|(k, va)| va.iter().zip(&tb[k]).map(|(x, y)| (x - y).abs()))
        .fold(0f32, f32::max)
}

/// `run/checkpoints/step_<N>`.
pub fn checkpoint(run: &Path, step: u64) -> PathBuf {
    run.join(format!("checkpoints/step_{step:08}"))
}

/// The tests' `tests/py/<name>`.
pub fn script(name: &str) -> PathBuf {
    workspace().join("tests/py").join(name)
}
