//! The one error type of the store: every variant names the URL it is about and says, on one
//! line, what went wrong and what to check (servers answer with multi-line XML; the codes in it
//! are picked out).

/// What can go wrong with object storage.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Not an object-store URL this crate reads (`s3://bucket/key` only).
    #[error("{url}: {reason}")]
    Url {
        /// The text given.
        url: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The AWS settings (environment, `~/.aws/config`, `~/.aws/credentials`) are unusable.
    #[error("{what}: {reason}")]
    Config {
        /// The file or variable.
        what: String,
        /// What is wrong.
        reason: String,
    },
    /// The bucket does not exist at this endpoint.
    #[error("{url}: no such bucket '{bucket}' at {endpoint} (check the name, AWS_ENDPOINT_URL and the region)")]
    NoSuchBucket {
        /// The URL asked for.
        url: String,
        /// The bucket.
        bucket: String,
        /// Where it was looked for.
        endpoint: String,
    },
    /// The object does not exist (any more: it may have been removed after it was listed).
    #[error("{url}: no such object")]
    NotFound {
        /// The URL.
        url: String,
    },
    /// The object changed while it was being read (another ETag than when it was opened).
    #[error("{url}: the object changed while it was being read (ETag {etag} when opened)")]
    Changed {
        /// The URL.
        url: String,
        /// Its ETag when it was opened.
        etag: String,
    },
    /// The endpoint refused the credentials (unknown key, wrong secret, expired token).
    #[error("{url}: the credentials were refused ({code}): check AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY / AWS_SESSION_TOKEN or the profile in use ({source_of_credentials})")]
    Credentials {
        /// The URL.
        url: String,
        /// The server's error code, e.g. `InvalidAccessKeyId`, `SignatureDoesNotMatch`.
        code: String,
        /// Where the credentials came from.
        source_of_credentials: String,
    },
    /// The credentials are valid but may not do this (a bucket or IAM policy denies it).
    #[error("{url}: access denied to {action} ({code}): the credentials in use ({source_of_credentials}) may not {action} here")]
    Denied {
        /// The URL.
        url: String,
        /// `read`, `list`, `write` or `delete`.
        action: &'static str,
        /// The server's error code, e.g. `AccessDenied`.
        code: String,
        /// Where the credentials came from.
        source_of_credentials: String,
    },
    /// The endpoint could not be reached or kept dropping the connection, after the retries.
    #[error("{url}: {reason}")]
    Network {
        /// The URL.
        url: String,
        /// What happened, with the retries made.
        reason: String,
    },
    /// Anything else the store answered.
    #[error("{url}: {reason}")]
    Other {
        /// The URL.
        url: String,
        /// The store's reason, on one line.
        reason: String,
    },
    /// A local file being uploaded or downloaded.
    #[error("{}: {source}", path.display())]
    Io {
        /// The local file.
        path: std::path::PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl Error {
    /// The URL (or local path) the error is about.
    pub fn url(&self) -> String {
        match self {
            Error::Url { url, .. }
            | Error::NoSuchBucket { url, .. }
            | Error::NotFound { url }
            | Error::Changed { url, .. }
            | Error::Credentials { url, .. }
            | Error::Denied { url, .. }
            | Error::Network { url, .. }
            | Error::Other { url, .. } => url.clone(),
            Error::Config { what, .. } => what.clone(),
            Error::Io { path, .. } => path.display().to_string(),
        }
    }

    /// True for an object that is not there (as opposed to a bucket, the network, rights).
    pub fn is_not_found(&self) -> bool {
        matches!(self, Error::NotFound { .. })
    }

    /// The message without the URL it starts with (for callers that name the object
    /// themselves).
    pub fn reason(&self) -> String {
        let text = self.to_string();
        let url = self.url();
        text.strip_prefix(&url)
            .and_then(|t| t.strip_prefix(": "))
            .map_or(text.clone(), str::to_string)
    }
}

/// Result with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The text of `e` and its sources, on one line, each repeated part dropped.
pub(crate) fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut next = Some(e);
    while let Some(err) = next {
        let text = err
            .to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        if !parts.iter().any(|p| p.contains(&text)) {
            parts.push(text);
        }
        next = err.source();
    }
    parts.join(": ")
}

/// `<Code>…</Code>` of an S3 error body, if the text holds one.
pub(crate) fn s3_code(text: &str) -> Option<String> {
    let start = text.find("<Code>")? + "<Code>".len();
    let end = text[start..].find("</Code>")? + start;
    Some(text[start..end].trim().to_string())
}

/// `<Code>: <Message>` of an S3 error body, if the text holds both.
pub(crate) fn s3_message(text: &str) -> Option<String> {
    let code = s3_code(text)?;
    let start = text.find("<Message>")? + "<Message>".len();
    let end = text[start..].find("</Message>")? + start;
    Some(format!("{code}: {}", text[start..end].trim()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_picked_out_of_s3_bodies() {
        let body = "Server returned 404: <?xml version=\"1.0\"?>\n<Error><Code>NoSuchBucket</Code>\
                    <Message>The specified bucket does not exist</Message></Error>";
        assert_eq!(s3_code(body).as_deref(), Some("NoSuchBucket"));
        assert_eq!(s3_code("connection refused"), None);
        assert_eq!(
            s3_message(body).as_deref(),
            Some("NoSuchBucket: The specified bucket does not exist")
        );
    }

    #[test]
    fn reason_drops_the_url() {
        let e = Error::NotFound {
            url: "s3://b/k.mcap".into(),
        };
        assert_eq!(e.to_string(), "s3://b/k.mcap: no such object");
        assert_eq!(e.reason(), "no such object");
        assert!(e.is_not_found());
    }
}
