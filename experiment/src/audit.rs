//! What every results file carries so that a reader can audit it without the machine it ran
//! on: which clean commit built the binary that trained and the one that scored (and that
//! binary's SHA-256), the exact commands, the machine, the simulator and its bridge, the seeds
//! the demonstrations were collected from, the training seed, and every episode's outcome
//! (seed, success, furthest stage, steps to success) from which the figures, intervals and
//! paired tests are recomputed. [`check_file`] is the schema: `experiment/tests/results.rs`
//! runs it on every committed file under `docs/results/` but `historical/`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::provenance::{git_revision, machine, now_utc};

/// The schema's version: files without it (or older) predate the audit and belong in
/// `docs/results/historical/`.
pub const SCHEMA: u32 = 2;

/// One evaluation episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The episode's seed.
    pub seed: u64,
    /// Whether it ended as a success.
    pub success: bool,
    /// A staged task's furthest stage (its name; `none` when it reached no stage).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highest_stage: Option<String>,
    /// Control ticks until the task became a success.
    pub steps_to_success: Option<u64>,
    /// Simulated seconds until the task became a success.
    pub time_to_success_s: Option<f64>,
}

/// Every episode of an evaluation report, in seed order.
pub fn outcomes(r: &scaledp_deploy::EvalReport) -> Vec<Outcome> {
    r.episodes
        .iter()
        .map(|e| Outcome {
            seed: e.seed,
            success: e.success,
            highest_stage: e.highest_stage.map(|h| {
                r.stages
                    .iter()
                    .rfind(|s| f64::from(s.number) <= h)
                    .map_or_else(|| "none".to_string(), |s| s.stage.clone())
            }),
            steps_to_success: e
                .time_to_success_s
                .map(|t| (t * r.control_rate_hz).round() as u64),
            time_to_success_s: e.time_to_success_s,
        })
        .collect()
}

/// A binary that ran: the clean commit it was built from, its hash, what it was asked, where
/// and when.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Binary {
    /// The full commit hash the binary was built from (`-dirty`: not a result).
    pub revision: String,
    /// SHA-256 of the executable (absent only for runs trained before binaries recorded it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
    /// The command line it ran.
    pub command: String,
    /// CPU model, cores, memory.
    pub machine: String,
    /// When it started (training) or finished (scoring), RFC 3339 UTC.
    pub utc: String,
}

impl Binary {
    /// This process: its binary's revision and hash, its command line, this machine, now.
    pub fn this() -> Self {
        Binary {
            revision: git_revision(),
            sha256: own_sha256(),
            command: command_line(),
            machine: machine(),
            utc: now_utc(),
        }
    }
}

/// `scaledp <args>` as this process was started (arguments quoted where a shell needs it).
pub fn command_line() -> String {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .map(|a| {
            if a.is_empty() || a.contains(|c: char| c.is_whitespace() || "'\"$`\\".contains(c)) {
                format!("'{}'", a.replace('\'', r"'\''"))
            } else {
                a
            }
        })
        .collect();
    format!("scaledp {}", args.join(" "))
}

/// SHA-256 of this executable, hex.
pub fn own_sha256() -> Option<String> {
    let exe = std::env::current_exe().ok()?;
    sha256_of(&exe).ok()
}

/// SHA-256 of a file, hex.
pub fn sha256_of(path: &Path) -> Result<String> {
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut h = Sha256::new();
    std::io::copy(&mut f, &mut h).with_context(|| format!("reading {}", path.display()))?;
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// Refuses to write a result from a binary built from a tree with uncommitted changes (or
/// outside a checkout): nobody could rebuild what ran.
pub fn refuse_dirty(what: &Path) -> Result<()> {
    let r = git_revision();
    if !is_clean_revision(&r) {
        bail!(
            "{}: this binary was built from {r}, not a clean commit; a result needs a binary \
             built from a committed tree (commit, rebuild, run again), or write it outside \
             docs/results with --results",
            what.display()
        );
    }
    Ok(())
}

/// A full 40-digit commit hash, without `-dirty`.
pub fn is_clean_revision(r: &str) -> bool {
    r.len() == 40 && r.chars().all(|c| c.is_ascii_hexdigit())
}

/// Where the demonstrations came from: the seeds `scaledp collect` used (successes kept,
/// failures skipped) and its command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Collection {
    /// Seeds of the demonstrations trained on.
    pub seeds: Vec<u64>,
    /// Seeds the expert failed on, skipped.
    pub failed_seeds: Vec<u64>,
    /// The command that collected them.
    pub command: String,
}

impl Collection {
    /// From a `collect.jsonl` manifest (one line per episode: `seed`, `outcome`, `episode`).
    pub fn read(demos: &Path, command: String) -> Result<Self> {
        let path = demos.join("collect.jsonl");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let (mut seeds, mut failed_seeds) = (Vec::new(), Vec::new());
        for (i, line) in text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
        {
            let v: serde_json::Value = serde_json::from_str(line)
                .with_context(|| format!("{}:{}: not JSON", path.display(), i + 1))?;
            let seed = v["seed"]
                .as_u64()
                .with_context(|| format!("{}:{}: no seed", path.display(), i + 1))?;
            if v["outcome"] == "success" && v["episode"].is_string() {
                seeds.push(seed);
            } else {
                failed_seeds.push(seed);
            }
        }
        Ok(Collection {
            seeds,
            failed_seeds,
            command,
        })
    }
}

/// The audit block of every results file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Audit {
    /// [`SCHEMA`].
    pub schema: u32,
    /// The binary that trained the checkpoints scored here (`None`: nothing trained, e.g. a
    /// scripted expert alone).
    pub trained_by: Option<Binary>,
    /// The binary that scored them.
    pub scored_by: Binary,
    /// The simulator's packages and its bridge's behaviour (`scaledp-bridge`).
    pub simulator: BTreeMap<String, String>,
    /// The demonstrations trained on.
    pub collection: Option<Collection>,
    /// The training seed.
    pub train_seed: Option<u64>,
}

/// The simulator that scored `r`: a bridged one's packages and bridge behaviour, or the
/// built-in one (whose version is the scoring binary's).
pub fn simulator(r: &scaledp_deploy::EvalReport) -> BTreeMap<String, String> {
    match &r.simulator {
        Some(s) if !s.is_empty() => s.clone(),
        _ => BTreeMap::from([("scaledp-sim".to_string(), "built in".to_string())]),
    }
}

impl Audit {
    /// A test fixture that passes the schema, trained from `train_seed`.
    #[cfg(test)]
    pub(crate) fn fixture(train_seed: u64) -> Self {
        let binary = Binary {
            revision: "0123456789abcdef0123456789abcdef01234567".into(),
            sha256: Some("ab".repeat(32)),
            command: "scaledp experiment compare".into(),
            machine: "test machine".into(),
            utc: "2026-11-28T00:00:00Z".into(),
        };
        Audit {
            schema: SCHEMA,
            trained_by: Some(binary.clone()),
            scored_by: binary,
            simulator: BTreeMap::from([("gym_aloha".into(), "0.1.1".into())]),
            collection: Some(Collection {
                seeds: (0..50).collect(),
                failed_seeds: Vec::new(),
                command: "scaledp collect".into(),
            }),
            train_seed: Some(train_seed),
        }
    }
}

/// What a training run records beside its checkpoints when it starts (`TRAINED_BY.json`).
pub fn record_trainer(run: &Path) -> Result<Binary> {
    let path = run.join("TRAINED_BY.json");
    if let Ok(bytes) = std::fs::read(&path) {
        return serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: not a trainer record", path.display()));
    }
    // Runs started before the record existed wrote their revision alone.
    if let Ok(r) = std::fs::read_to_string(run.join("REVISION")) {
        return Ok(Binary {
            revision: r.trim().to_string(),
            sha256: None,
            command: "(recorded before TRAINED_BY.json: see the file's train_command)".into(),
            machine: machine(),
            utc: "unknown".into(),
        });
    }
    std::fs::create_dir_all(run).with_context(|| format!("creating {}", run.display()))?;
    let b = Binary::this();
    crate::provenance::write_json(&path, &b)?;
    std::fs::write(run.join("REVISION"), format!("{}\n", b.revision))
        .with_context(|| format!("writing {}", run.display()))?;
    Ok(b)
}

/// Checks one committed results file against the schema; the first fault, naming the file and
/// the field.
pub fn check_file(path: &Path) -> Result<()> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_slice(&bytes).with_context(|| format!("{}: not JSON", path.display()))?;
    check_value(&v).with_context(|| path.display().to_string())
}

fn field<'a>(v: &'a serde_json::Value, name: &str) -> Result<&'a serde_json::Value> {
    match v.get(name) {
        Some(serde_json::Value::Null) | None => bail!("no `{name}`"),
        Some(x) => Ok(x),
    }
}

fn check_binary(v: &serde_json::Value, who: &str, needs_hash: bool) -> Result<()> {
    let b: Binary = serde_json::from_value(v.clone()).with_context(|| format!("`{who}`"))?;
    if !is_clean_revision(&b.revision) {
        bail!("`{who}.revision` {:?} is not a clean commit", b.revision);
    }
    if needs_hash && b.sha256.as_deref().is_none_or(|h| h.len() != 64) {
        bail!("`{who}.sha256` missing");
    }
    if b.command.trim().is_empty() || b.machine.trim().is_empty() {
        bail!("`{who}` has no command or machine");
    }
    Ok(())
}

/// The schema on a parsed file: the audit block, and every evaluation in it (any object with
/// `first_seed`, `episodes` and `successes`) listing each episode's outcome consistently.
pub fn check_value(v: &serde_json::Value) -> Result<()> {
    let audit = field(v, "audit")?;
    let schema = field(audit, "schema")?.as_u64().unwrap_or(0);
    if schema != u64::from(SCHEMA) {
        bail!("`audit.schema` is {schema}, not {SCHEMA}");
    }
    check_binary(field(audit, "scored_by")?, "audit.scored_by", true)?;
    if let Some(t) = audit.get("trained_by").filter(|t| !t.is_null()) {
        check_binary(t, "audit.trained_by", false)?;
        field(audit, "train_seed")?;
        let c: Collection = serde_json::from_value(field(audit, "collection")?.clone())
            .context("`audit.collection`")?;
        if c.seeds.is_empty() {
            bail!("`audit.collection.seeds` is empty");
        }
    }
    if field(audit, "simulator")?
        .as_object()
        .is_none_or(|m| m.is_empty())
    {
        bail!("`audit.simulator` is empty");
    }
    let mut evals = 0;
    walk(v, &mut |e| {
        evals += 1;
        check_eval(e)
    })?;
    if evals == 0 {
        bail!("no evaluation in the file");
    }
    Ok(())
}

fn walk(v: &serde_json::Value, f: &mut dyn FnMut(&serde_json::Value) -> Result<()>) -> Result<()> {
    match v {
        serde_json::Value::Object(m) => {
            if m.contains_key("first_seed") && m.contains_key("successes") {
                return f(v);
            }
            // What a file said before a re-score is history, not this file's figures.
            for (k, x) in m.iter().filter(|(k, _)| *k != "earlier_scores") {
                walk(x, f).with_context(|| format!("in `{k}`"))?;
            }
        }
        serde_json::Value::Array(a) => {
            for x in a {
                walk(x, f)?;
            }
        }
        _ => {}
    }
    Ok(())
}

fn check_eval(e: &serde_json::Value) -> Result<()> {
    let n = field(e, "episodes")?.as_u64().context("`episodes`")?;
    let k = field(e, "successes")?.as_u64().context("`successes`")?;
    let first = field(e, "first_seed")?.as_u64().context("`first_seed`")?;
    let outcomes: Vec<Outcome> =
        serde_json::from_value(field(e, "outcomes")?.clone()).context("`outcomes`")?;
    if outcomes.len() as u64 != n {
        bail!("{} outcomes for {n} episodes", outcomes.len());
    }
    if outcomes.iter().filter(|o| o.success).count() as u64 != k {
        bail!("the outcomes hold another count of successes than {k}");
    }
    for (i, o) in outcomes.iter().enumerate() {
        if o.seed != first + i as u64 {
            bail!("outcome {i} has seed {}, not {}", o.seed, first + i as u64);
        }
        if o.success != o.steps_to_success.is_some() {
            bail!(
                "outcome {i} (seed {}): success without steps, or steps without success",
                o.seed
            );
        }
    }
    // Reported figures on the test range, pilots on the validation range; nothing on the
    // development range (the old test range, which pilots saw) or across ranges.
    use scaledp_deploy::Split;
    if !matches!(Split::of(first, n), Some(Split::Test | Split::Val)) {
        bail!(
            "seeds {first}… lie in neither the test range (3 000 000 …) nor the validation range"
        );
    }
    Ok(())
}
