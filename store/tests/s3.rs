//! The store against a real S3 endpoint (moto from the tests' venv, loopback, IAM auth, set up
//! by `tests/py/s3_setup.py`) through a proxy that cuts uploads: a file above the part size goes
//! up as a multipart upload that survives a cut part and is aborted when the endpoint keeps
//! cutting (nothing appears); the prefetching reader and ranged reads return the object's bytes;
//! a read of an object replaced since it was listed is an error, not a mix.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::sync::atomic::Ordering;

use scaledp_store::{Bucket, Error, ObjectReader, ObjectUrl, S3Settings, PART_BYTES};
use scaledp_testkit::{python, run_python, workspace_root, Moto, Proxy};

fn settings(endpoint: &str, keys: &serde_json::Value) -> S3Settings {
    S3Settings {
        endpoint: Some(endpoint.into()),
        region: Some("us-east-1".into()),
        keys: Some((
            keys["writer"]["id"].as_str().unwrap().into(),
            keys["writer"]["secret"].as_str().unwrap().into(),
            None,
        )),
        credentials_from: "the test's key".into(),
    }
}

fn url(key: &str) -> ObjectUrl {
    ObjectUrl {
        bucket: "data".into(),
        key: key.into(),
    }
}

#[test]
fn multipart_uploads_survive_a_cut_and_reads_are_pinned_to_the_listed_version() {
    let dir = tempfile::tempdir().unwrap();
    let moto = Moto::start(&python(), &workspace_root(), &dir.path().join("moto.log")).unwrap();
    let keys = run_python("s3_setup.py", &[std::path::Path::new(&moto.endpoint)]);
    let proxy = Proxy::start(&moto.endpoint);
    let bucket = Bucket::connect_with("data", &settings(&proxy.endpoint, &keys)).unwrap();

    // Two and a half parts of pseudo-random bytes; the second part's first attempt is cut.
    let bytes: Vec<u8> = (0..PART_BYTES * 5 / 2)
        .map(|i| {
            (i as u64)
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .rotate_left(17) as u8
        })
        .collect();
    let file = dir.path().join("big.bin");
    std::fs::write(&file, &bytes).unwrap();
    proxy.state.cut_uploads.store(1, Ordering::SeqCst);
    assert_eq!(
        bucket.upload(&file, &url("big.bin")).unwrap(),
        bytes.len() as u64
    );
    let requests = proxy.requests();
    assert!(
        requests.iter().any(|r| r.contains("big.bin?uploads")),
        "{requests:?}"
    );
    let parts = requests
        .iter()
        .filter(|r| r.contains("partNumber="))
        .count();
    assert!(parts >= 4, "3 parts and a retried one: {requests:?}");
    assert!(bucket.get(&url("big.bin")).unwrap().unwrap() == bytes);

    // Cut for good: an error naming the object, the upload aborted, no object.
    proxy.state.cut_uploads.store(usize::MAX, Ordering::SeqCst);
    let e = bucket.upload(&file, &url("never.bin")).unwrap_err();
    assert!(matches!(e, Error::Network { .. }), "{e}");
    assert!(
        e.to_string()
            .starts_with("s3://data/never.bin: network error"),
        "{e}"
    );
    proxy.state.cut_uploads.store(0, Ordering::SeqCst);
    assert!(bucket.head(&url("never.bin")).unwrap().is_none());
    assert!(proxy
        .requests()
        .iter()
        .any(|r| r.starts_with("DELETE /data/never.bin?uploadId=")));

    // Reads of the listed version.
    let info = bucket
        .list(&url(""))
        .unwrap()
        .into_iter()
        .find(|i| i.url.key == "big.bin")
        .unwrap();
    let mut reader = ObjectReader::new(std::sync::Arc::new(bucket), info.clone()).unwrap();
    let mut back = Vec::new();
    std::io::Read::read_to_end(&mut reader, &mut back).unwrap();
    assert!(back == bytes, "the prefetching reader");
    let bucket = Bucket::connect_with("data", &settings(&moto.endpoint, &keys)).unwrap();
    let ranges = [
        5..10,
        (PART_BYTES as u64 - 3)..(PART_BYTES as u64 + 3),
        0..1,
    ];
    let got = bucket.get_ranges(&info, &ranges).unwrap();
    for (r, g) in ranges.iter().zip(&got) {
        assert_eq!(&g[..], &bytes[r.start as usize..r.end as usize]);
    }
    bucket
        .put(&url("big.bin"), b"replaced".to_vec().into())
        .unwrap();
    let e = bucket.get_range(&info, 0..4).unwrap_err();
    assert!(matches!(e, Error::Changed { .. }), "{e}");

    let missing = Bucket::connect_with("no-such-bucket", &settings(&moto.endpoint, &keys)).unwrap();
    let e = missing
        .list(&ObjectUrl::parse("s3://no-such-bucket/x/").unwrap())
        .unwrap_err();
    assert!(matches!(e, Error::NoSuchBucket { .. }), "{e}");
    assert!(bucket.get(&url("nothing-here")).unwrap().is_none());
}
