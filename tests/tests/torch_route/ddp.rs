//! DDP on the CPU: two gloo ranks on loopback train what one process trains with the same
//! global batch (each rank its disjoint half, together the whole batch; the weights after the
//! run equal within float32 reduction noise), and a 2-rank run killed with SIGKILL resumes from
//! its last checkpoint and ends where an uninterrupted one ends.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use serde_json::Value;

use super::{
    checkpoint, fixture, kill_tree, max_weight_diff, run_ok, spawn_group, train_cmd, TINY,
};

/// Steps of every run here: one epoch of the fixture's full batches of 8 and one step more.
const STEPS: u64 = 13;
const STEPS_ARG: &str = "13";
const LIMIT: Duration = Duration::from_secs(300);

/// The lines of a `.jsonl` file.
fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// (episode_index, frame_index) pairs of each step of a `samples-rank<R>.jsonl`.
fn samples(run: &Path, rank: usize) -> Vec<Vec<(i64, i64)>> {
    lines(&run.join(format!("samples-rank{rank}.jsonl")))
        .iter()
        .map(|l| {
            let r = &l["record"];
            let e = r["episode_index"].as_array().unwrap();
            let f = r["frame_index"].as_array().unwrap();
            e.iter()
                .zip(f)
                .map(|(e, f)| (e.as_i64().unwrap(), f.as_i64().unwrap()))
                .collect()
        })
        .collect()
}

/// `train` records of a run's `metrics.jsonl`.
fn train_records(run: &Path) -> Vec<Value> {
    lines(&run.join("metrics.jsonl"))
        .into_iter()
        .filter(|l| l["kind"] == "train")
        .map(|l| l["record"].clone())
        .collect()
}

fn args<'a>(ds: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut v = vec![ds, "--out", out, "--steps", STEPS_ARG, "--log-samples"];
    v.extend_from_slice(TINY);
    v.extend_from_slice(extra);
    v
}

/// The single-process run and the uninterrupted 2-rank run (made once, shared by the tests).
pub fn reference_runs() -> &'static (PathBuf, PathBuf) {
    static RUNS: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    RUNS.get_or_init(|| {
        let f = fixture();
        let ds = f.dataset.to_str().unwrap();
        let (one, two) = (f.dir.join("one-rank"), f.dir.join("two-ranks"));
        let t0 = Instant::now();
        run_ok(train_cmd(1, &args(ds, one.to_str().unwrap(), &[])), LIMIT);
        let t1 = Instant::now();
        run_ok(train_cmd(2, &args(ds, two.to_str().unwrap(), &[])), LIMIT);
        eprintln!(
            "{STEPS} steps: 1 process {:.1} s, 2 gloo ranks {:.1} s (wall, start-up included)",
            (t1 - t0).as_secs_f64(),
            t1.elapsed().as_secs_f64()
        );
        (one, two)
    })
}

#[test]
fn two_gloo_ranks_split_the_batch_and_end_with_one_processs_weights() {
    let (one, two) = reference_runs();
    let single = samples(one, 0);
    let (r0, r1) = (samples(two, 0), samples(two, 1));
    assert_eq!(single.len() as u64, STEPS);
    assert_eq!((r0.len() as u64, r1.len() as u64), (STEPS, STEPS));
    // Each step: rank 0 and rank 1 hold disjoint halves whose union is the single process's
    // batch (rank r takes rows r, r + 2, ... of it).
    for (k, ((s, a), b)) in single.iter().zip(&r0).zip(&r1).enumerate() {
        assert_eq!((a.len(), b.len()), (4, 4), "step {}", k + 1);
        let rows: Vec<(i64, i64)> = a.iter().zip(b).flat_map(|(x, y)| [*x, *y]).collect();
        assert_eq!(
            &rows,
            s,
            "step {}: the ranks' rows interleave into the batch",
            k + 1
        );
    }
    // Over the first epoch (12 full batches of 8): the ranks never share a sample, and together
    // they see every sample of those batches, each once.
    let records = train_records(two);
    let epoch0 = records.iter().filter(|r| r["epoch"] == 0).count();
    let (s0, s1): (BTreeSet<_>, BTreeSet<_>) = (
        r0[..epoch0].iter().flatten().copied().collect(),
        r1[..epoch0].iter().flatten().copied().collect(),
    );
    assert!(s0.is_disjoint(&s1), "a sample on both ranks in epoch 0");
    assert_eq!(s0.len() + s1.len(), epoch0 * 8, "a sample twice on a rank");
    let n = scaledp_datasets::LoaderOptions::default()
        .open(fixture().dataset.to_str().unwrap())
        .unwrap()
        .len();
    assert_eq!(
        epoch0,
        n / 8,
        "epoch 0 of {n} samples has {} full batches",
        n / 8
    );
    eprintln!(
        "epoch 0: {} + {} samples on ranks 0 and 1, disjoint, {} of the dataset's {n} (the rest fill no full batch)",
        s0.len(),
        s1.len(),
        s0.len() + s1.len()
    );
    // The same losses and, after the run, the same weights up to float32 reduction order.
    let single_records = train_records(one);
    for (a, b) in single_records.iter().zip(&records) {
        let (la, lb) = (a["loss"].as_f64().unwrap(), b["loss"].as_f64().unwrap());
        assert!(
            (la - lb).abs() <= 1e-5 * la.abs(),
            "step {}: {la} vs {lb}",
            a["step"]
        );
        assert_eq!(a["samples"], b["samples"]);
    }
    let ck = |run: &Path, f: &str| checkpoint(run, STEPS).join(f);
    let raw = max_weight_diff(
        &ck(one, "train_state.safetensors"),
        &ck(two, "train_state.safetensors"),
    );
    let ema = max_weight_diff(&ck(one, "model.safetensors"), &ck(two, "model.safetensors"));
    eprintln!("after {STEPS} steps, 1 process vs 2 gloo ranks: max |Δ| weights and AdamW moments {raw:.3e}, EMA weights {ema:.3e}");
    // lr 1e-4 with 2 warm-up steps: an update moves a weight by at most ~1e-4.
    assert!(raw <= 2e-6 && ema <= 2e-6, "{raw} {ema}");
    for r in &records {
        let w = r["data_wait_s_per_rank"].as_array().unwrap();
        assert_eq!((r["ranks"].as_u64(), w.len()), (Some(2), 2), "{r}");
    }
}

#[test]
fn a_killed_two_rank_run_resumes_from_its_checkpoint_and_ends_as_an_uninterrupted_one() {
    let (_, two) = reference_runs();
    let f = fixture();
    let ds = f.dataset.to_str().unwrap();
    let run = f.dir.join("killed");
    let out = run.to_str().unwrap();
    let mut child = spawn_group(&mut train_cmd(
        2,
        &args(ds, out, &["--checkpoint-every", "3"]),
    ));
    // Kill the whole job (torchrun and both workers) once the first checkpoint is complete.
    let first = checkpoint(&run, 3);
    let t0 = Instant::now();
    while !first.join("config.json").exists() {
        assert!(t0.elapsed() < LIMIT, "no checkpoint after {LIMIT:?}");
        if let Some(st) = child.try_wait().unwrap() {
            panic!("the run ended ({st}) before its first checkpoint");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    kill_tree(child.id());
    let status = child.wait().unwrap();
    assert!(!status.success(), "the run was not killed: {status}");
    assert!(
        !checkpoint(&run, STEPS).exists(),
        "the run finished before the kill: nothing to resume"
    );
    // Nothing of the job survives: no more steps appear.
    let done_before = train_records(&run).len();
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(
        train_records(&run).len(),
        done_before,
        "a worker outlived the kill"
    );
    assert!((done_before as u64) < STEPS);
    let t = Instant::now();
    let o = run_ok(train_cmd(2, &["--resume", out, "--log-samples"]), LIMIT);
    eprintln!(
        "killed after {done_before} logged steps (checkpoint at 3); resumed to {STEPS} in {:.1} s: {}",
        t.elapsed().as_secs_f64(),
        String::from_utf8_lossy(&o.stdout).trim()
    );
    // Every step logged once, with the uninterrupted run's losses and samples.
    let (a, b) = (train_records(&run), train_records(two));
    let steps: Vec<u64> = a.iter().map(|r| r["step"].as_u64().unwrap()).collect();
    assert_eq!(steps, (1..=STEPS).collect::<Vec<_>>());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x["loss"], y["loss"], "step {}", x["step"]);
    }
    for rank in 0..2 {
        assert_eq!(samples(&run, rank), samples(two, rank), "rank {rank}");
    }
    let ck = |r: &Path, f: &str| checkpoint(r, STEPS).join(f);
    for file in ["train_state.safetensors", "model.safetensors"] {
        let d = max_weight_diff(&ck(&run, file), &ck(two, file));
        assert_eq!(
            d, 0.0,
            "{file}: the resumed run ends {d} away from the uninterrupted one"
        );
    }
}
