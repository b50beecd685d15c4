//! How a bucket's failures read: one line naming the URL, the action, the bucket's endpoint
//! and where its credentials came from, with S3's own code and message when it gave one.

use crate::error::{chain, s3_code, s3_message, Error};
use crate::location::{ObjectInfo, ObjectUrl};

/// What errors of a bucket mention: its name, endpoint, where its credentials come from.
pub(crate) struct Describe {
    pub(crate) name: String,
    pub(crate) endpoint: String,
    pub(crate) credentials_from: String,
}

impl Describe {
    /// An object_store error on `url` while trying to `action` as one [`Error`].
    pub(crate) fn error(
        &self,
        url: &ObjectUrl,
        action: &'static str,
        e: object_store::Error,
    ) -> Error {
        let text = chain(&e);
        let code = s3_code(&text);
        let url_text = url.to_string();
        let credential_codes = [
            "InvalidAccessKeyId",
            "SignatureDoesNotMatch",
            "ExpiredToken",
            "InvalidToken",
            "TokenRefreshRequired",
            "AuthorizationHeaderMalformed",
        ];
        // List requests come back as generic errors whatever the status: the S3 code decides
        // first, then the kind object_store gave.
        let kind = match (&e, code.as_deref()) {
            (_, Some("NoSuchBucket")) => "bucket",
            (_, Some("NoSuchKey" | "NotFound")) | (object_store::Error::NotFound { .. }, None) => {
                "object"
            }
            (_, Some(c)) if credential_codes.contains(&c) => "credentials",
            (_, Some("AccessDenied" | "AllAccessDisabled" | "AccountProblem")) => "denied",
            (
                object_store::Error::PermissionDenied { .. }
                | object_store::Error::Unauthenticated { .. },
                _,
            ) => "denied",
            (object_store::Error::NotFound { .. }, Some(_)) => "object",
            (_, None)
                if [
                    "error sending request",
                    "connect",
                    "timed out",
                    "Connection",
                    "reset",
                    "closed",
                ]
                .iter()
                .any(|w| text.contains(w)) =>
            {
                "network"
            }
            _ => "other",
        };
        let code = code.unwrap_or_else(|| "HTTP 403".into());
        match kind {
            "bucket" => Error::NoSuchBucket {
                url: url_text,
                bucket: self.name.clone(),
                endpoint: self.endpoint.clone(),
            },
            "object" => Error::NotFound { url: url_text },
            "credentials" => Error::Credentials {
                url: url_text,
                code,
                source_of_credentials: self.credentials_from.clone(),
            },
            "denied" => Error::Denied {
                url: url_text,
                action,
                code,
                source_of_credentials: self.credentials_from.clone(),
            },
            "network" => Error::Network {
                url: url_text,
                reason: format!(
                    "network error talking to {} (gave up after the retries): {text}",
                    self.endpoint
                ),
            },
            _ => Error::Other {
                url: url_text,
                reason: s3_message(&text).unwrap_or(text),
            },
        }
    }

    /// A read error, a failed `If-Match` becoming [`Error::Changed`].
    pub(crate) fn read_error(&self, info: &ObjectInfo, e: object_store::Error) -> Error {
        match (&e, &info.etag) {
            (object_store::Error::Precondition { .. }, Some(etag)) => Error::Changed {
                url: info.url.to_string(),
                etag: etag.clone(),
            },
            _ => self.error(&info.url, "read", e),
        }
    }
}
