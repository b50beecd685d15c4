//! The S3 settings from the standard AWS environment and shared files, in the AWS SDKs' order:
//! `AWS_*` variables first, then the profile (`AWS_PROFILE`, else `default`) of
//! `~/.aws/credentials` (`AWS_SHARED_CREDENTIALS_FILE`) and `~/.aws/config` (`AWS_CONFIG_FILE`)
//! for the keys, session token, `region` and `endpoint_url` (also a `services` section's
//! `s3 = endpoint_url = …`), then what object_store finds itself: web identity (EKS IRSA), ECS /
//! EKS Pod Identity container credentials, the EC2 instance metadata. The endpoint:
//! `AWS_ENDPOINT_URL_S3`, else `AWS_ENDPOINT_URL`, else the profile's (none of them with
//! `AWS_IGNORE_CONFIGURED_ENDPOINT_URLS=true`); an `http://` endpoint is allowed as given.
//!
//! Profiles that get their keys from `sso_*`, `credential_process` or `role_arn` are not
//! evaluated here: that is the AWS CLI's job (`aws configure export-credentials --format env`),
//! and the error says so. The shared files are read by the small parser below rather than
//! the AWS SDK's, whose dependency tree is larger than the rest of this crate's: the format is
//! INI with `[profile name]` sections in the config file and indented sub-settings.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Everything needed to build an S3 client, resolved.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct S3Settings {
    /// The endpoint URL (None: AWS S3 itself).
    pub endpoint: Option<String>,
    /// The region (None: object_store's default, `us-east-1`).
    pub region: Option<String>,
    /// Static keys: (access key id, secret, session token).
    pub keys: Option<(String, String, Option<String>)>,
    /// Where the credentials come from, for messages (`AWS_ACCESS_KEY_ID`, `profile 'x' of
    /// ~/.aws/credentials`, `the instance or container role`).
    pub credentials_from: String,
}

/// A section of a shared AWS file: its settings, sub-settings under `name.key`.
type Section = BTreeMap<String, String>;

/// Parses an AWS shared config or credentials file into sections. Sub-settings (an indented
/// line after `s3 =`) become `s3.key`. Comments start with `#` or `;`.
fn parse_ini(text: &str) -> BTreeMap<String, Section> {
    let mut out: BTreeMap<String, Section> = BTreeMap::new();
    let mut section: Option<String> = None;
    let mut parent: Option<String> = None;
    for raw in text.lines() {
        let line = strip_comment(raw).trim_end();
        if line.trim().is_empty() {
            continue;
        }
        let indented = line.starts_with([' ', '\t']);
        let line = line.trim();
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            section = Some(name.split_whitespace().collect::<Vec<_>>().join(" "));
            parent = None;
            continue;
        }
        let (Some(sec), Some((k, v))) = (&section, line.split_once('=')) else {
            continue;
        };
        let (k, v) = (k.trim().to_ascii_lowercase(), v.trim().to_string());
        let entry = out.entry(sec.clone()).or_default();
        match (&parent, indented) {
            (Some(p), true) => {
                entry.insert(format!("{p}.{k}"), v);
            }
            _ if v.is_empty() => parent = Some(k),
            _ => {
                parent = None;
                entry.insert(k, v);
            }
        }
    }
    out
}

/// `line` without a comment: one starts the line (after blanks) or follows a blank, as the AWS
/// CLI reads them (a `#` inside a value, e.g. of a secret, is kept).
fn strip_comment(line: &str) -> &str {
    let mut prev_blank = true;
    for (i, c) in line.char_indices() {
        if (c == '#' || c == ';') && prev_blank {
            return &line[..i];
        }
        prev_blank = c.is_whitespace();
    }
    line
}

/// The files and profile in use, and their parsed sections.
struct SharedFiles {
    profile: String,
    explicit_profile: bool,
    config_path: PathBuf,
    credentials_path: PathBuf,
    config: BTreeMap<String, Section>,
    credentials: BTreeMap<String, Section>,
}

impl SharedFiles {
    fn read(env: &dyn Fn(&str) -> Option<String>, home: Option<&Path>) -> Result<Self> {
        let path = |var: &str, name: &str| {
            env(var)
                .map(PathBuf::from)
                .or_else(|| home.map(|h| h.join(".aws").join(name)))
                .unwrap_or_default()
        };
        let config_path = path("AWS_CONFIG_FILE", "config");
        let credentials_path = path("AWS_SHARED_CREDENTIALS_FILE", "credentials");
        let load = |p: &Path| -> Result<BTreeMap<String, Section>> {
            match std::fs::read_to_string(p) {
                Ok(text) => Ok(parse_ini(&text)),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(BTreeMap::new()),
                Err(e) if p.as_os_str().is_empty() => Err(Error::Config {
                    what: "AWS shared files".into(),
                    reason: e.to_string(),
                }),
                Err(e) => Err(Error::Config {
                    what: p.display().to_string(),
                    reason: e.to_string(),
                }),
            }
        };
        let explicit = env("AWS_PROFILE").or_else(|| env("AWS_DEFAULT_PROFILE"));
        Ok(Self {
            explicit_profile: explicit.is_some(),
            profile: explicit.unwrap_or_else(|| "default".into()),
            config: load(&config_path)?,
            credentials: load(&credentials_path)?,
            config_path,
            credentials_path,
        })
    }

    /// The profile's section of the config file (`[profile x]`, or `[default]`).
    fn config_section(&self) -> Option<&Section> {
        let named = format!("profile {}", self.profile);
        self.config.get(&named).or_else(|| {
            (self.profile == "default")
                .then(|| self.config.get("default"))
                .flatten()
        })
    }

    /// A setting of the profile: the credentials file first, then the config file.
    fn get(&self, key: &str) -> Option<&String> {
        self.credentials
            .get(&self.profile)
            .and_then(|s| s.get(key))
            .or_else(|| self.config_section().and_then(|s| s.get(key)))
    }

    /// The profile's S3 endpoint: `services` → `s3.endpoint_url`, else its `endpoint_url`.
    fn endpoint(&self) -> Option<String> {
        let services = self.config_section().and_then(|s| s.get("services"));
        let from_services = services
            .and_then(|name| self.config.get(&format!("services {name}")))
            .and_then(|s| s.get("s3.endpoint_url"));
        from_services
            .or_else(|| self.get("endpoint_url"))
            .filter(|e| !e.is_empty())
            .cloned()
    }
}

impl S3Settings {
    /// Resolves the settings from this process's environment and `$HOME/.aws`.
    pub fn from_env() -> Result<Self> {
        let home = std::env::var_os("HOME").map(PathBuf::from);
        Self::resolve(
            &|k| std::env::var(k).ok().filter(|v| !v.is_empty()),
            home.as_deref(),
        )
    }

    /// Resolves the settings from `env` (variable → value) and `home` (for `~/.aws`).
    pub fn resolve(env: &dyn Fn(&str) -> Option<String>, home: Option<&Path>) -> Result<Self> {
        let files = SharedFiles::read(env, home)?;
        let in_files =
            files.credentials.contains_key(&files.profile) || files.config_section().is_some();
        if files.explicit_profile && !in_files {
            return Err(Error::Config {
                what: format!("AWS_PROFILE={}", files.profile),
                reason: format!(
                    "no such profile in {} or {}",
                    files.config_path.display(),
                    files.credentials_path.display()
                ),
            });
        }
        let ignore_endpoints = env("AWS_IGNORE_CONFIGURED_ENDPOINT_URLS")
            .is_some_and(|v| v.eq_ignore_ascii_case("true"));
        let endpoint = if ignore_endpoints {
            None
        } else {
            env("AWS_ENDPOINT_URL_S3")
                .or_else(|| env("AWS_ENDPOINT_URL"))
                .or_else(|| env("AWS_ENDPOINT"))
                .or_else(|| files.endpoint())
        };
        let region = env("AWS_REGION")
            .or_else(|| env("AWS_DEFAULT_REGION"))
            .or_else(|| files.get("region").cloned());
        let env_keys = match (env("AWS_ACCESS_KEY_ID"), env("AWS_SECRET_ACCESS_KEY")) {
            (Some(id), Some(secret)) => Some((id, secret, env("AWS_SESSION_TOKEN"))),
            (Some(_), None) | (None, Some(_)) => {
                return Err(Error::Config {
                    what: "AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY".into(),
                    reason: "only one of the two is set".into(),
                })
            }
            (None, None) => None,
        };
        let (keys, credentials_from) = match env_keys {
            Some(k) => (Some(k), "AWS_ACCESS_KEY_ID".to_string()),
            None => match (
                files.get("aws_access_key_id"),
                files.get("aws_secret_access_key"),
            ) {
                (Some(id), Some(secret)) => (
                    Some((
                        id.clone(),
                        secret.clone(),
                        files.get("aws_session_token").cloned(),
                    )),
                    format!("profile '{}' of the AWS shared files", files.profile),
                ),
                _ => {
                    let indirect = [
                        "sso_session",
                        "sso_start_url",
                        "credential_process",
                        "role_arn",
                    ]
                    .into_iter()
                    .find(|k| files.get(k).is_some());
                    if let (Some(k), false) =
                        (indirect, env("AWS_WEB_IDENTITY_TOKEN_FILE").is_some())
                    {
                        return Err(Error::Config {
                            what: format!("profile '{}'", files.profile),
                            reason: format!(
                                "its credentials come from `{k}`, which scaledp does not \
                                 evaluate: run `eval \"$(aws configure export-credentials \
                                 --profile {} --format env)\"` first",
                                files.profile
                            ),
                        });
                    }
                    (
                        None,
                        "the web identity, container or instance role".to_string(),
                    )
                }
            },
        };
        Ok(Self {
            endpoint,
            region,
            keys,
            credentials_from,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env_of<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(name, _)| *name == k)
                .map(|(_, v)| v.to_string())
        }
    }

    fn home_with(config: &str, credentials: &str) -> tempfile::TempDir {
        let home = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(home.path().join(".aws")).unwrap();
        std::fs::write(home.path().join(".aws/config"), config).unwrap();
        std::fs::write(home.path().join(".aws/credentials"), credentials).unwrap();
        home
    }

    const CONFIG: &str = "[default]\nregion = eu-west-1\n\n[profile lab]\nregion = us-west-2 # ours\n\
                          services = lab-minio\n\n[services lab-minio]\ns3 =\n  endpoint_url = http://minio:9000\n\n\
                          [profile sso]\nsso_session = corp\n";
    const CREDENTIALS: &str = "[default]\naws_access_key_id = AKIADEFAULT\naws_secret_access_key = s1\n\n\
                               [lab]\naws_access_key_id = AKIALAB\naws_secret_access_key = s2\naws_session_token = t2\n";

    #[test]
    fn comments_need_a_blank_before_them() {
        assert_eq!(strip_comment("key = a#b ; note"), "key = a#b ");
        assert_eq!(strip_comment("# all"), "");
        assert_eq!(strip_comment("  ; all"), "  ");
    }

    #[test]
    fn environment_wins_over_the_shared_files() {
        let home = home_with(CONFIG, CREDENTIALS);
        let vars = [
            ("AWS_ACCESS_KEY_ID", "AKIAENV"),
            ("AWS_SECRET_ACCESS_KEY", "s0"),
            ("AWS_ENDPOINT_URL", "http://127.0.0.1:9"),
            ("AWS_REGION", "ap-south-1"),
        ];
        let s = S3Settings::resolve(&env_of(&vars), Some(home.path())).unwrap();
        assert_eq!(s.keys, Some(("AKIAENV".into(), "s0".into(), None)));
        assert_eq!(s.endpoint.as_deref(), Some("http://127.0.0.1:9"));
        assert_eq!(s.region.as_deref(), Some("ap-south-1"));
        assert_eq!(s.credentials_from, "AWS_ACCESS_KEY_ID");
    }

    #[test]
    fn the_profile_gives_keys_region_and_service_endpoint() {
        let home = home_with(CONFIG, CREDENTIALS);
        let s = S3Settings::resolve(&env_of(&[]), Some(home.path())).unwrap();
        assert_eq!(s.keys, Some(("AKIADEFAULT".into(), "s1".into(), None)));
        assert_eq!(
            (s.region.as_deref(), s.endpoint.as_deref()),
            (Some("eu-west-1"), None)
        );
        let vars = [("AWS_PROFILE", "lab")];
        let s = S3Settings::resolve(&env_of(&vars), Some(home.path())).unwrap();
        assert_eq!(
            s.keys,
            Some(("AKIALAB".into(), "s2".into(), Some("t2".into())))
        );
        assert_eq!(s.region.as_deref(), Some("us-west-2"));
        assert_eq!(s.endpoint.as_deref(), Some("http://minio:9000"));
        assert!(s.credentials_from.contains("profile 'lab'"));
        let vars = [
            ("AWS_PROFILE", "lab"),
            ("AWS_IGNORE_CONFIGURED_ENDPOINT_URLS", "true"),
        ];
        let s = S3Settings::resolve(&env_of(&vars), Some(home.path())).unwrap();
        assert_eq!(s.endpoint, None);
    }

    #[test]
    fn unusable_settings_are_one_clear_line() {
        let home = home_with(CONFIG, CREDENTIALS);
        let e = |vars: &[(&str, &str)]| {
            S3Settings::resolve(&env_of(vars), Some(home.path()))
                .unwrap_err()
                .to_string()
        };
        assert!(e(&[("AWS_PROFILE", "nope")]).contains("no such profile"));
        assert!(e(&[("AWS_PROFILE", "sso")]).contains("export-credentials --profile sso"));
        assert!(e(&[("AWS_ACCESS_KEY_ID", "x")]).contains("only one of the two"));
        // No files at all: nothing static, object_store's own chain decides.
        let empty = tempfile::tempdir().unwrap();
        let s = S3Settings::resolve(&env_of(&[]), Some(empty.path())).unwrap();
        assert_eq!(s.keys, None);
    }
}
