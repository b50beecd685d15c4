//! S3-compatible storage: a dataset uploaded to a local `moto_server` (loopback, from the
//! project's .venv — scripts/setup-python.sh installs it) opens as `s3://bucket/prefix` with the
//! standard AWS_* variables and yields the same batches as the local copy, in random-access and
//! streaming mode, reading only a sample's pages; a missing prefix is one line naming the URL.
//! Behind a proxy that drops connections in the middle of a response, a read is retried, and
//! an endpoint that keeps dropping them is one clear error (or skipped samples, counted) within
//! seconds, never a hang.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
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

/// A TCP proxy in front of an endpoint that cuts connections: while `drops` is above zero,
/// each response is cut after its first 200 bytes (a server or network that drops the
/// connection mid-read), and `drops` counts down.
struct Proxy {
    endpoint: String,
    drops: Arc<AtomicUsize>,
}

impl Proxy {
    fn start(upstream: &str) -> Proxy {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let endpoint = format!("http://{}", listener.local_addr().unwrap());
        let upstream = upstream.trim_start_matches("http://").to_string();
        let drops = Arc::new(AtomicUsize::new(0));
        let d = drops.clone();
        std::thread::spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else { return };
                let Ok(server) = TcpStream::connect(&upstream) else {
                    continue;
                };
                let (c2, s2) = (client.try_clone().unwrap(), server.try_clone().unwrap());
                std::thread::spawn(move || pump(c2, s2, None));
                let d = d.clone();
                std::thread::spawn(move || pump(server, client, Some(d)));
            }
        });
        Proxy { endpoint, drops }
    }
}

/// Copies `from` to `to` until either closes; a response direction (`drops` given) is cut while
/// drops are armed.
fn pump(mut from: TcpStream, mut to: TcpStream, drops: Option<Arc<AtomicUsize>>) {
    let mut buf = vec![0u8; 64 << 10];
    loop {
        let n = match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        let cut = drops.as_ref().is_some_and(|d| {
            d.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |k| k.checked_sub(1))
                .is_ok()
        });
        if cut {
            let _ = to.write_all(&buf[..n.min(200)]);
            break;
        }
        if to.write_all(&buf[..n]).is_err() {
            break;
        }
    }
    let _ = from.shutdown(Shutdown::Both);
    let _ = to.shutdown(Shutdown::Both);
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

    // Through a proxy that drops connections mid-response. (This test owns the variables.)
    let proxy = Proxy::start(&moto.endpoint);
    std::env::set_var("AWS_ENDPOINT_URL", &proxy.endpoint);
    let (local, _) = epoch(opts.clone(), &ds.location());
    // One dropped response: the read is retried and the epoch is the same.
    let mut l = opts.clone().open(url).unwrap();
    l.set_epoch(1);
    proxy.drops.store(1, Ordering::Relaxed);
    let got: Vec<Batch> = l.iter().map(Result::unwrap).collect();
    assert!(got == local, "a retried read gives the same batches");
    // Every response dropped: one clear error within seconds.
    let mut l = opts.clone().open(url).unwrap();
    l.set_epoch(1);
    proxy.drops.store(usize::MAX, Ordering::Relaxed);
    let t0 = Instant::now();
    let e = l
        .iter()
        .find_map(Result::err)
        .expect("an error")
        .to_string();
    let took = t0.elapsed();
    assert!(
        e.contains("s3://scaledp-test/sets/small/data/") && !e.contains('\n'),
        "{e}"
    );
    assert!(took < Duration::from_secs(40), "failed after {took:?}");
    // Skipped when allowed: the epoch ends, every sample counted as skipped.
    proxy.drops.store(0, Ordering::Relaxed);
    let few = opts.clone().max_episodes(1).skip_bad_samples(1000);
    let mut l = few.open(url).unwrap();
    proxy.drops.store(usize::MAX, Ordering::Relaxed);
    let t0 = Instant::now();
    let kept: usize = l.iter().map(|b| b.unwrap().len).sum();
    assert_eq!(kept, 0);
    assert_eq!(l.skipped_samples(), l.len() as u64);
    assert!(t0.elapsed() < Duration::from_secs(60), "{:?}", t0.elapsed());
    drop(moto);
}
