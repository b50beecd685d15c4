//! The shared tokio runtime every bucket's requests run on, entered from synchronous callers
//! (the converter's and loader's threads are not async), and the retry policy of every request.

use std::future::Future;
use std::sync::OnceLock;
use std::time::Duration;

use crate::error::{Error, Result};

/// The retry policy of every request: object_store retries connection errors, timeouts of
/// safe requests and 5xx / throttling answers with exponential backoff (0.2 s doubling up to 5
/// s, jittered), at most `SCALEDP_S3_RETRIES` times (default 5) and for at most
/// `SCALEDP_S3_RETRY_TIMEOUT_S` seconds (default 60) from the first attempt.
pub fn retry_config() -> object_store::RetryConfig {
    let var = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<u64>().ok());
    object_store::RetryConfig {
        backoff: object_store::BackoffConfig {
            init_backoff: Duration::from_millis(200),
            max_backoff: Duration::from_secs(5),
            base: 2.0,
        },
        max_retries: var("SCALEDP_S3_RETRIES").map_or(5, |n| n as usize),
        retry_timeout: Duration::from_secs(var("SCALEDP_S3_RETRY_TIMEOUT_S").unwrap_or(60)),
    }
}

/// The runtime every bucket's requests run on (two I/O threads; the work is waiting).
fn runtime() -> Result<&'static tokio::runtime::Runtime> {
    static RT: OnceLock<std::result::Result<tokio::runtime::Runtime, String>> = OnceLock::new();
    RT.get_or_init(|| {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("scaledp-store")
            .enable_all()
            .build()
            .map_err(|e| e.to_string())
    })
    .as_ref()
    .map_err(|e| Error::Config {
        what: "object storage".into(),
        reason: format!("cannot start the I/O runtime: {e}"),
    })
}

/// Runs `f` to completion on the shared runtime from a synchronous caller.
pub(crate) fn block<F: Future>(f: F) -> Result<F::Output> {
    Ok(runtime()?.block_on(f))
}

/// Starts `f` on the shared runtime.
pub(crate) fn spawn<F>(f: F) -> Result<tokio::task::JoinHandle<F::Output>>
where
    F: Future + Send + 'static,
    F::Output: Send + 'static,
{
    Ok(runtime()?.spawn(f))
}
