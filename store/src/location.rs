//! Where data lives: a local path or an `s3://bucket/key` URL. Command lines take either; a
//! text starting with a scheme (`xyz://`) is a URL, anything else a path.

use std::ffi::OsStr;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// An object (or a prefix of objects) in an S3-compatible store.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ObjectUrl {
    /// The bucket.
    pub bucket: String,
    /// The key, without a leading `/`; a prefix may end in `/` or not; empty for the bucket.
    pub key: String,
}

impl ObjectUrl {
    /// Parses `s3://bucket[/key]`.
    pub fn parse(url: &str) -> Result<Self> {
        let bad = |reason: &str| Error::Url {
            url: url.into(),
            reason: reason.into(),
        };
        let Some((scheme, rest)) = url.split_once("://") else {
            return Err(bad("not a URL"));
        };
        if scheme != "s3" {
            return Err(bad(
                "only s3:// URLs are read (any S3-compatible store: set AWS_ENDPOINT_URL)",
            ));
        }
        let (bucket, key) = rest.split_once('/').unwrap_or((rest, ""));
        let valid = |c: char| c.is_ascii_lowercase() || c.is_ascii_digit() || "-.".contains(c);
        if bucket.len() < 3 || bucket.len() > 63 || !bucket.chars().all(valid) {
            return Err(bad(
                "a bucket name is 3-63 lowercase letters, digits, '-' or '.'",
            ));
        }
        let key = key.trim_start_matches('/');
        if key.split('/').rev().skip(1).any(str::is_empty) {
            return Err(bad("empty path segment ('//') in the key"));
        }
        Ok(Self {
            bucket: bucket.into(),
            key: key.into(),
        })
    }

    /// The key as a prefix of the objects under it: empty, or ending in `/`.
    pub fn prefix(&self) -> String {
        if self.key.is_empty() || self.key.ends_with('/') {
            self.key.clone()
        } else {
            format!("{}/", self.key)
        }
    }

    /// The object `rel` under this prefix (`rel` uses `/`).
    pub fn join(&self, rel: &str) -> ObjectUrl {
        ObjectUrl {
            bucket: self.bucket.clone(),
            key: format!("{}{}", self.prefix(), rel.trim_start_matches('/')),
        }
    }

    /// The last segment of the key (the object's file name), empty for a bucket.
    pub fn file_name(&self) -> &str {
        self.key
            .trim_end_matches('/')
            .rsplit('/')
            .next()
            .unwrap_or("")
    }

    /// The URL as a path, for the error types and records that name inputs by path (the text
    /// is kept as is: `s3://bucket/key`).
    pub fn as_path(&self) -> PathBuf {
        PathBuf::from(self.to_string())
    }
}

impl fmt::Display for ObjectUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "s3://{}/{}", self.bucket, self.key)
    }
}

/// A local path or an object-store URL.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Location {
    /// A local file or directory.
    Local(PathBuf),
    /// An object or prefix in an S3-compatible store.
    Object(ObjectUrl),
}

impl Location {
    /// `s3://…` as a URL (other schemes are refused), anything else as a local path.
    pub fn parse(text: &OsStr) -> Result<Self> {
        match text.to_str() {
            Some(s) if s.contains("://") => ObjectUrl::parse(s).map(Location::Object),
            _ => Ok(Location::Local(PathBuf::from(text))),
        }
    }

    /// The local path, if this is one.
    pub fn local(&self) -> Option<&Path> {
        match self {
            Location::Local(p) => Some(p),
            Location::Object(_) => None,
        }
    }

    /// The path, or the URL as a path (see [`ObjectUrl::as_path`]).
    pub fn as_path(&self) -> PathBuf {
        match self {
            Location::Local(p) => p.clone(),
            Location::Object(u) => u.as_path(),
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Local(p) => write!(f, "{}", p.display()),
            Location::Object(u) => write!(f, "{u}"),
        }
    }
}

/// One object as listed: its URL, size and ETag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectInfo {
    /// Where it is.
    pub url: ObjectUrl,
    /// Bytes.
    pub size: u64,
    /// Its ETag (the store's fingerprint of this version), when the store gives one.
    pub etag: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_and_paths() {
        let u = ObjectUrl::parse("s3://my-bucket/recordings/day1/").unwrap();
        assert_eq!(
            (u.bucket.as_str(), u.key.as_str()),
            ("my-bucket", "recordings/day1/")
        );
        assert_eq!(u.prefix(), "recordings/day1/");
        assert_eq!(
            u.join("ep.mcap").to_string(),
            "s3://my-bucket/recordings/day1/ep.mcap"
        );
        assert_eq!(u.join("ep.mcap").file_name(), "ep.mcap");
        let root = ObjectUrl::parse("s3://bucket").unwrap();
        assert_eq!((root.key.as_str(), root.prefix()), ("", String::new()));
        assert_eq!(root.join("a/b").key, "a/b");
        assert_eq!(
            Location::parse(OsStr::new("demos/x.mcap")).unwrap(),
            Location::Local("demos/x.mcap".into())
        );
        assert!(matches!(
            Location::parse(OsStr::new("s3://bucket/k")).unwrap(),
            Location::Object(_)
        ));
    }

    #[test]
    fn bad_urls_say_why() {
        let e = |s: &str| Location::parse(OsStr::new(s)).unwrap_err().to_string();
        assert!(
            e("gs://bucket/k").contains("only s3:// URLs"),
            "{}",
            e("gs://b/k")
        );
        assert!(e("s3://Bucket_Name/k").contains("bucket name"));
        assert!(e("s3://bucket/a//b").contains("empty path segment"));
    }
}
