//! A bucket's client: listing by prefix, whole and ranged reads pinned to the ETag seen when
//! an object was listed (so a replaced object is an error, not a mix of two versions), small
//! puts, multipart uploads of files, server-side copies and deletes. Every request is retried
//! with exponential backoff by object_store ([`retry_config`]); what still fails becomes one
//! [`Error`] line naming the URL. Calls block the calling thread on a shared tokio runtime (the
//! converter's and loader's threads are not async).

use std::collections::HashMap;
use std::future::Future;
use std::ops::Range;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

use bytes::Bytes;
use futures::stream::{FuturesUnordered, StreamExt, TryStreamExt};
use object_store::path::Path as Key;
use object_store::{GetOptions, GetRange, ObjectStore, PutPayload};

use crate::config::S3Settings;
use crate::describe::Describe;
use crate::error::{chain, Error, Result};
use crate::location::{ObjectInfo, ObjectUrl};
use crate::runtime::{block, retry_config};

/// Size of each part of a multipart upload (S3 wants at least 5 MiB but for the last part); a
/// file no larger than this is one PUT.
pub const PART_BYTES: usize = 8 << 20;
/// Parts of one upload in flight at once.
const PARTS_IN_FLIGHT: usize = 4;
/// Ranged reads of one call in flight at once.
const RANGES_IN_FLIGHT: usize = 8;

/// A client for one bucket.
pub struct Bucket {
    store: Arc<dyn ObjectStore>,
    describe: Arc<Describe>,
}

impl std::fmt::Debug for Bucket {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Bucket({} at {})",
            self.describe.name, self.describe.endpoint
        )
    }
}

impl Bucket {
    /// The client of `bucket` with the settings of this process's AWS environment and files
    /// (resolved once; one client per bucket per process, sharing its connections).
    pub fn connect(bucket: &str) -> Result<Arc<Bucket>> {
        static SETTINGS: OnceLock<std::result::Result<S3Settings, String>> = OnceLock::new();
        static BUCKETS: OnceLock<Mutex<HashMap<String, Arc<Bucket>>>> = OnceLock::new();
        let settings = SETTINGS
            .get_or_init(|| S3Settings::from_env().map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|reason| Error::Config {
                what: "AWS settings".into(),
                reason: reason.clone(),
            })?;
        let mut buckets = BUCKETS
            .get_or_init(Default::default)
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        if let Some(b) = buckets.get(bucket) {
            return Ok(b.clone());
        }
        let b = Arc::new(Bucket::connect_with(bucket, settings)?);
        buckets.insert(bucket.into(), b.clone());
        Ok(b)
    }

    /// A client of `bucket` with explicit `settings` (not cached).
    pub fn connect_with(bucket: &str, settings: &S3Settings) -> Result<Bucket> {
        let mut b = object_store::aws::AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .with_retry(retry_config());
        if let Some(e) = &settings.endpoint {
            b = b.with_endpoint(e).with_allow_http(e.starts_with("http://"));
        }
        if let Some(r) = &settings.region {
            b = b.with_region(r);
        }
        if let Some((id, secret, token)) = &settings.keys {
            b = b.with_access_key_id(id).with_secret_access_key(secret);
            if let Some(t) = token {
                b = b.with_token(t);
            }
        }
        let store = b.build().map_err(|e| Error::Config {
            what: format!("s3://{bucket}"),
            reason: chain(&e),
        })?;
        let endpoint = settings.endpoint.clone().unwrap_or_else(|| {
            format!(
                "AWS S3 ({})",
                settings.region.as_deref().unwrap_or("us-east-1")
            )
        });
        Ok(Bucket {
            store: Arc::new(store),
            describe: Arc::new(Describe {
                name: bucket.into(),
                endpoint,
                credentials_from: settings.credentials_from.clone(),
            }),
        })
    }

    /// The bucket's name.
    pub fn name(&self) -> &str {
        &self.describe.name
    }

    /// An object_store error on `url` while trying to `action` as one [`Error`].
    pub(crate) fn error(
        &self,
        url: &ObjectUrl,
        action: &'static str,
        e: object_store::Error,
    ) -> Error {
        self.describe.error(url, action, e)
    }

    fn read_error(&self, info: &ObjectInfo, e: object_store::Error) -> Error {
        self.describe.read_error(info, e)
    }

    fn key(&self, url: &ObjectUrl) -> Result<Key> {
        Key::parse(&url.key).map_err(|e| Error::Url {
            url: url.to_string(),
            reason: chain(&e),
        })
    }

    /// Every object under `prefix` (recursively), sorted by key.
    pub fn list(&self, prefix: &ObjectUrl) -> Result<Vec<ObjectInfo>> {
        let key = self.key(prefix)?;
        let listed: Vec<_> = block(async {
            self.store
                .list(Some(&key))
                .try_collect::<Vec<_>>()
                .await
                .map_err(|e| self.error(prefix, "list", e))
        })??;
        let mut out: Vec<ObjectInfo> = listed
            .into_iter()
            .map(|m| ObjectInfo {
                url: ObjectUrl {
                    bucket: self.name().into(),
                    key: m.location.to_string(),
                },
                size: m.size,
                etag: m.e_tag,
            })
            .collect();
        out.sort_by(|a, b| a.url.key.cmp(&b.url.key));
        Ok(out)
    }

    /// The object at `url`, or None when there is none.
    pub fn head(&self, url: &ObjectUrl) -> Result<Option<ObjectInfo>> {
        let key = self.key(url)?;
        match block(self.store.head(&key))? {
            Ok(m) => Ok(Some(ObjectInfo {
                url: url.clone(),
                size: m.size,
                etag: m.e_tag,
            })),
            Err(object_store::Error::NotFound { .. }) => Ok(None),
            Err(e) => Err(self.error(url, "read", e)),
        }
    }

    fn get_options(info: &ObjectInfo, range: Option<Range<u64>>) -> GetOptions {
        GetOptions {
            if_match: info.etag.clone(),
            range: range.map(GetRange::Bounded),
            ..Default::default()
        }
    }

    /// The whole object at `url`, or None when there is none.
    pub fn get(&self, url: &ObjectUrl) -> Result<Option<Bytes>> {
        let key = self.key(url)?;
        let got = block(async {
            let r = self.store.get(&key).await?;
            r.bytes().await
        })?;
        match got {
            Ok(b) => Ok(Some(b)),
            Err(object_store::Error::NotFound { .. }) => {
                // Tell a missing bucket from a missing object (a GET of one has a body).
                let err = block(self.store.get(&key))?.err();
                match err.map(|e| self.error(url, "read", e)) {
                    Some(e @ Error::NoSuchBucket { .. }) => Err(e),
                    _ => Ok(None),
                }
            }
            Err(e) => Err(self.error(url, "read", e)),
        }
    }

    /// Bytes `range` of the object, as it was when `info` was taken.
    pub fn get_range(&self, info: &ObjectInfo, range: Range<u64>) -> Result<Bytes> {
        let mut v = self.get_ranges(info, std::slice::from_ref(&range))?;
        Ok(v.pop().unwrap_or_default())
    }

    /// Several ranges of the object (as it was when `info` was taken), fetched concurrently, in
    /// the order asked.
    pub fn get_ranges(&self, info: &ObjectInfo, ranges: &[Range<u64>]) -> Result<Vec<Bytes>> {
        let key = self.key(&info.url)?;
        block(async {
            futures::stream::iter(ranges.iter().cloned())
                .map(|r| self.fetch(&key, info, r))
                .buffered(RANGES_IN_FLIGHT)
                .try_collect()
                .await
        })?
    }

    /// One ranged GET.
    pub(crate) fn fetch(
        &self,
        key: &Key,
        info: &ObjectInfo,
        range: Range<u64>,
    ) -> impl Future<Output = Result<Bytes>> + Send + 'static {
        let (store, key, describe) = (self.store.clone(), key.clone(), self.describe.clone());
        let (options, info) = (Self::get_options(info, Some(range)), info.clone());
        async move {
            let got = async { store.get_opts(&key, options).await?.bytes().await }.await;
            got.map_err(|e| describe.read_error(&info, e))
        }
    }

    /// The object_store key of `info`, for [`crate::ObjectReader`].
    pub(crate) fn key_of(&self, info: &ObjectInfo) -> Result<Key> {
        self.key(&info.url)
    }

    /// Writes `bytes` as the object `url` (one PUT: the object appears whole or not at all).
    pub fn put(&self, url: &ObjectUrl, bytes: Bytes) -> Result<()> {
        let key = self.key(url)?;
        block(self.store.put(&key, PutPayload::from(bytes)))?
            .map(drop)
            .map_err(|e| self.error(url, "write", e))
    }

    /// Uploads the local file `path` as `url`: one PUT up to [`PART_BYTES`], else a multipart
    /// upload of [`PART_BYTES`] parts, a few in flight, aborted (its parts removed) on failure.
    /// The object appears only once the upload completes. Returns the bytes uploaded.
    pub fn upload(&self, path: &Path, url: &ObjectUrl) -> Result<u64> {
        use std::io::Read;
        let io = |source| Error::Io {
            path: path.into(),
            source,
        };
        let mut file = std::fs::File::open(path).map_err(io)?;
        let size = file.metadata().map_err(io)?.len();
        if size <= PART_BYTES as u64 {
            let mut buf = Vec::with_capacity(size as usize);
            file.read_to_end(&mut buf).map_err(io)?;
            self.put(url, buf.into())?;
            return Ok(size);
        }
        let key = self.key(url)?;
        block(async {
            let mut upload = self
                .store
                .put_multipart(&key)
                .await
                .map_err(|e| self.error(url, "write", e))?;
            let result: Result<()> = async {
                let mut parts: FuturesUnordered<object_store::UploadPart> = FuturesUnordered::new();
                loop {
                    let mut buf = Vec::with_capacity(PART_BYTES);
                    (&mut file)
                        .take(PART_BYTES as u64)
                        .read_to_end(&mut buf)
                        .map_err(io)?;
                    if buf.is_empty() {
                        break;
                    }
                    if parts.len() >= PARTS_IN_FLIGHT {
                        if let Some(r) = parts.next().await {
                            r.map_err(|e| self.error(url, "write", e))?;
                        }
                    }
                    parts.push(upload.put_part(PutPayload::from(buf)));
                }
                while let Some(r) = parts.next().await {
                    r.map_err(|e| self.error(url, "write", e))?;
                }
                Ok(())
            }
            .await;
            let completed = match result {
                Ok(()) => upload
                    .complete()
                    .await
                    .map(drop)
                    .map_err(|e| self.error(url, "write", e)),
                Err(e) => Err(e),
            };
            if completed.is_err() {
                if let Err(e) = upload.abort().await {
                    tracing::warn!(
                        "{url}: the failed upload could not be aborted: {}",
                        chain(&e)
                    );
                }
            }
            completed
        })??;
        Ok(size)
    }

    /// Copies `from` to `to` inside the bucket (server side; up to S3's 5 GB for one copy).
    pub fn copy(&self, from: &ObjectUrl, to: &ObjectUrl) -> Result<()> {
        let (a, b) = (self.key(from)?, self.key(to)?);
        block(self.store.copy(&a, &b))?.map_err(|e| self.error(to, "write", e))
    }

    /// Deletes the objects `urls` (missing ones are no error).
    pub fn delete(&self, urls: &[ObjectUrl]) -> Result<()> {
        let keys = urls
            .iter()
            .map(|u| self.key(u))
            .collect::<Result<Vec<_>>>()?;
        let first = urls.first().cloned();
        block(async {
            let stream = futures::stream::iter(keys.into_iter().map(Ok)).boxed();
            let mut deleted = self.store.delete_stream(stream);
            while let Some(r) = deleted.next().await {
                match r {
                    Ok(_) | Err(object_store::Error::NotFound { .. }) => {}
                    Err(e) => {
                        let url = first.clone().unwrap_or_else(|| ObjectUrl {
                            bucket: self.name().into(),
                            key: String::new(),
                        });
                        return Err(self.error(&url, "delete", e));
                    }
                }
            }
            Ok(())
        })?
    }

    /// Downloads the object to the local file `path` (as it was when `info` was taken).
    pub fn download(&self, info: &ObjectInfo, path: &Path) -> Result<()> {
        use std::io::Write;
        let io = |source| Error::Io {
            path: path.into(),
            source,
        };
        let key = self.key(&info.url)?;
        let mut file = std::fs::File::create(path).map_err(io)?;
        block(async {
            let got = self
                .store
                .get_opts(&key, Self::get_options(info, None))
                .await
                .map_err(|e| self.read_error(info, e))?;
            let mut stream = got.into_stream();
            while let Some(chunk) = stream.next().await {
                let chunk = chunk.map_err(|e| self.read_error(info, e))?;
                file.write_all(&chunk).map_err(io)?;
            }
            file.sync_all().map_err(io)
        })?
    }
}
