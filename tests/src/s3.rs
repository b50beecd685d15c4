//! A real S3 endpoint for the object-storage tests: moto from the tests' venv on loopback,
//! prepared by `tests/py/s3_setup.py` (buckets `data` and `locked`, IAM auth on, a `writer`
//! key that may not write to `locked`), one per test binary ([`shared`]), and the helpers the
//! tests use around it: the `scaledp` command with the AWS variables of that endpoint, uploads,
//! and every object under a prefix read back.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, OnceLock};

use scaledp_store::{Bucket, ObjectUrl, S3Settings};
use scaledp_testkit::Moto;

use crate::{run_python, scaledp_bin, workspace};

/// The endpoint and the writer's key.
pub struct S3Env {
    _moto: Moto,
    /// moto's own endpoint, `http://127.0.0.1:<port>`.
    pub endpoint: String,
    /// The writer's access key id.
    pub key_id: String,
    /// Its secret.
    pub secret: String,
}

/// The test binary's S3 endpoint, started on first use (moto exits with the test process).
pub fn shared() -> &'static S3Env {
    static ENV: OnceLock<S3Env> = OnceLock::new();
    ENV.get_or_init(S3Env::start)
}

impl S3Env {
    /// Starts and prepares moto.
    ///
    /// # Panics
    /// When moto cannot start (run `bash scripts/setup-python.sh`).
    pub fn start() -> S3Env {
        let log = std::env::temp_dir().join(format!("scaledp-moto-{}.log", std::process::id()));
        let moto = Moto::start(&crate::python(), &workspace(), &log)
            .unwrap_or_else(|e| panic!("{e} (bash scripts/setup-python.sh installs moto)"));
        let keys = run_python("s3_setup.py", &[Path::new(&moto.endpoint)]);
        S3Env {
            endpoint: moto.endpoint.clone(),
            key_id: keys["writer"]["id"].as_str().expect("a key id").into(),
            secret: keys["writer"]["secret"].as_str().expect("a secret").into(),
            _moto: moto,
        }
    }

    /// The settings a client of `endpoint` (moto's, or a proxy's in front of it) uses.
    pub fn settings(&self, endpoint: &str) -> S3Settings {
        S3Settings {
            endpoint: Some(endpoint.into()),
            region: Some("us-east-1".into()),
            keys: Some((self.key_id.clone(), self.secret.clone(), None)),
            credentials_from: "the test's writer key".into(),
        }
    }

    /// A client of `bucket` straight at moto.
    pub fn bucket(&self, bucket: &str) -> Arc<Bucket> {
        Arc::new(Bucket::connect_with(bucket, &self.settings(&self.endpoint)).expect("a client"))
    }

    /// `scaledp` with the AWS variables of `endpoint` and the writer's key (nothing else of
    /// the caller's AWS environment), retrying twice within 10 s so that failures are quick.
    pub fn scaledp(&self, endpoint: &str) -> Command {
        self.command(&scaledp_bin(), endpoint)
    }

    /// `program` with the environment of [`Self::scaledp`] (a script that runs scaledp).
    pub fn command(&self, program: &Path, endpoint: &str) -> Command {
        let mut c = Command::new(program);
        for (k, _) in std::env::vars_os() {
            if k.to_string_lossy().starts_with("AWS_") {
                c.env_remove(k);
            }
        }
        c.env("AWS_ENDPOINT_URL", endpoint)
            .env("AWS_ACCESS_KEY_ID", &self.key_id)
            .env("AWS_SECRET_ACCESS_KEY", &self.secret)
            .env("AWS_REGION", "us-east-1")
            .env("SCALEDP_S3_RETRIES", "2")
            .env("SCALEDP_S3_RETRY_TIMEOUT_S", "10")
            .stdin(std::process::Stdio::null());
        c
    }

    /// Uploads every file under `dir` to `url`/<relative path>.
    pub fn upload_dir(&self, dir: &Path, url: &ObjectUrl) {
        let bucket = self.bucket(&url.bucket);
        for (rel, p) in walk(dir) {
            bucket.upload(&p, &url.join(&rel)).expect("an upload");
        }
    }

    /// Every object under `url`, by key relative to it.
    pub fn objects(&self, url: &ObjectUrl) -> BTreeMap<String, Vec<u8>> {
        let bucket = self.bucket(&url.bucket);
        let prefix = url.prefix();
        bucket
            .list(url)
            .expect("a listing")
            .into_iter()
            .map(|i| {
                let bytes = bucket.get(&i.url).expect("a read").expect("the object");
                let rel = i
                    .url
                    .key
                    .strip_prefix(&prefix)
                    .unwrap_or(&i.url.key)
                    .to_string();
                (rel, bytes.to_vec())
            })
            .collect()
    }
}

/// `s3://<bucket>/<key>`.
pub fn url(bucket: &str, key: &str) -> ObjectUrl {
    ObjectUrl {
        bucket: bucket.into(),
        key: key.into(),
    }
}

/// Every file under `dir`, by path relative to it (as [`S3Env::objects`] lists a prefix).
pub fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    walk(dir)
        .into_iter()
        .map(|(rel, p)| (rel, std::fs::read(&p).expect("a file")))
        .collect()
}

/// Every file under `dir`: its path relative to `dir` and its path.
fn walk(dir: &Path) -> Vec<(String, PathBuf)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("a directory").flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).expect("under dir").to_string_lossy();
                out.push((rel.into_owned(), p));
            }
        }
    }
    out
}
