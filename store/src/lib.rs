//! Object storage for scaledp: where recordings and datasets live when they are not on a local
//! disk. A [`Location`] is a local path or an `s3://bucket/key` URL (any S3-compatible store:
//! AWS, MinIO, Ceph, R2, …); a [`Bucket`] is the client of one bucket, configured from the
//! standard AWS environment and shared files ([`S3Settings`]: keys, profile, region,
//! endpoint), with bounded retries and exponential backoff on every request
//! ([`retry_config`]).
//!
//! # The API
//!
//! - [`Bucket::list`] lists by prefix, [`Bucket::head`] / [`Bucket::get`] look one object up;
//! - [`Bucket::get_ranges`] and [`ObjectReader`] (a prefetching front-to-back [`std::io::Read`])
//!   read an object as it was listed: a replaced object is [`Error::Changed`], never a mix;
//! - [`Bucket::put`] writes a small object, [`Bucket::upload`] a file (multipart above
//!   [`PART_BYTES`], aborted on failure), [`Bucket::copy`] and [`Bucket::delete`] finish a
//!   publication, [`Bucket::download`] fetches an object to a file;
//! - every failure is one [`Error`] line naming the URL and what to check (no such bucket,
//!   refused credentials, access denied, the network after the retries).

mod bucket;
mod config;
mod describe;
mod error;
mod location;
mod reader;
mod runtime;

pub use bucket::{Bucket, PART_BYTES};
pub use config::S3Settings;
pub use error::{Error, Result};
pub use location::{Location, ObjectInfo, ObjectUrl};
pub use reader::{ObjectReader, BLOCKS_AHEAD, BLOCK_BYTES};
pub use runtime::retry_config;
