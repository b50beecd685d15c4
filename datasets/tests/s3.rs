//! S3-compatible storage: a dataset uploaded to a local `moto_server` (loopback, from the
//! project's .venv — scripts/setup-python.sh installs it) opens as `s3://bucket/prefix` with the
//! standard AWS_* variables and yields the same batches as the local copy, in random-access and
//! streaming mode, reading only a sample's pages; a missing prefix is one line naming the URL.
#![allow(clippy::unwrap_used)]

mod common;

use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::Fixture;
use scaledp_datasets::{Batch, LoaderOptions};

/// The venv's bin directory (the tests' Python, `SCALEDP_PYTHON` overriding it).
fn venv_bin() -> PathBuf {
    scaledp_testkit::python().parent().unwrap().to_path_buf()
}

/// A moto S3 server on 127.0.0.1, killed when dropped.
struct Moto {
    child: Child,
    endpoint: String,
}

impl Moto {
    fn start(log: &Path) -> Moto {
        let port = scaledp_testkit::free_port().unwrap();
        let server = venv_bin().join("moto_server");
        assert!(
            server.exists(),
            "{} is missing: moto[server] is in tests/py/requirements.txt",
            server.display()
        );
        let child = Command::new(server)
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(log).unwrap())
            .spawn()
            .unwrap();
        let mut moto = Moto {
            child,
            endpoint: format!("http://127.0.0.1:{port}"),
        };
        let addr: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
        let deadline = Instant::now() + Duration::from_secs(60);
        while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
            let exited = moto.child.try_wait().unwrap();
            assert!(
                exited.is_none() && Instant::now() < deadline,
                "moto_server did not start: {}",
                std::fs::read_to_string(log).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        moto
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Creates `bucket` and uploads every file under `root` to `bucket/prefix/...` with boto3.
fn upload(endpoint: &str, bucket: &str, root: &Path, prefix: &str) {
    let script = r#"
import os, sys, boto3
endpoint, bucket, root, prefix = sys.argv[1:5]
s3 = boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1",
                  aws_access_key_id="testing", aws_secret_access_key="testing")
s3.create_bucket(Bucket=bucket)
for d, _, files in os.walk(root):
    for f in files:
        path = os.path.join(d, f)
        s3.upload_file(path, bucket, prefix + "/" + os.path.relpath(path, root))
"#;
    let out = Command::new(venv_bin().join("python"))
        .args([
            "-c",
            script,
            endpoint,
            bucket,
            root.to_str().unwrap(),
            prefix,
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "upload failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn epoch(o: LoaderOptions, location: &str) -> (Vec<Batch>, u64) {
    let mut l = o.open(location).unwrap();
    l.set_epoch(1);
    let b = l.iter().map(Result::unwrap).collect();
    (b, l.bytes_read())
}

#[test]
fn s3_dataset_yields_the_same_batches_as_the_local_copy() {
    let ds = common::write(&Fixture {
        lens: vec![7, 2, 12, 5, 9],
        episodes_per_file: 2,
        png: false,
        ..Fixture::default()
    });
    let log = ds.dir.path().join("moto.log");
    let moto = Moto::start(&log);
    upload(&moto.endpoint, "scaledp-test", &ds.root, "sets/small");
    // The variables a user sets for any S3-compatible store; this test binary is the only user.
    for (k, v) in [
        ("AWS_ENDPOINT_URL", moto.endpoint.as_str()),
        ("AWS_ACCESS_KEY_ID", "testing"),
        ("AWS_SECRET_ACCESS_KEY", "testing"),
        ("AWS_REGION", "us-east-1"),
        ("AWS_ALLOW_HTTP", "true"),
    ] {
        std::env::set_var(k, v);
    }
    let url = "s3://scaledp-test/sets/small";
    let opts = LoaderOptions::default()
        .obs_horizon(2)
        .action_chunk(4)
        .batch_size(6)
        .seed(3);
    for o in [
        opts.clone(),
        opts.clone().streaming(2),
        opts.clone().rank(1, 2).cameras(vec!["wrist".into()]),
    ] {
        let (local, local_bytes) = epoch(o.clone(), &ds.location());
        let (remote, remote_bytes) = epoch(o, url);
        assert!(!local.is_empty());
        assert!(local == remote, "S3 batches differ from the local ones");
        // The same pages are read either way (ranges of the same files).
        assert_eq!(local_bytes, remote_bytes);
    }
    let l = opts.clone().open(url).unwrap();
    assert_eq!(l.info().location, url);
    assert_eq!(l.info().episodes, [0, 1, 2, 3, 4]);

    let e = opts
        .clone()
        .open("s3://scaledp-test/sets/missing")
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("s3://scaledp-test/sets/missing")
            && e.contains("info.json")
            && !e.contains('\n'),
        "{e}"
    );
    drop(moto);
}
