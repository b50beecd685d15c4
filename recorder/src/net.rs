//! Zenoh session configuration shared by the recorder and the simulator.

use std::path::Path;

use crate::error::{Error, Result};

/// The endpoint zenoh-bridge-ros2dds (and `scaledp sim`) listens on by default.
pub const DEFAULT_ENDPOINT: &str = "tcp/127.0.0.1:7447";

/// The endpoint of a session only its own process uses: loopback, on a port the OS picks when
/// Zenoh binds it (a port probed free beforehand can be taken by another process in between).
pub const PRIVATE_ENDPOINT: &str = "tcp/127.0.0.1:0";

/// Opens a session only this process uses (a simulator, a server and a recorder sharing it):
/// it listens on [`PRIVATE_ENDPOINT`] and connects nowhere.
pub fn open_private() -> Result<zenoh::Session> {
    open(zenoh_config(None, &[], &[PRIVATE_ENDPOINT.to_string()])?)
}

/// Builds a Zenoh config: from a standard Zenoh config file when given (endpoints, TLS, …),
/// else peer mode on loopback with multicast scouting off. `connect` / `listen` endpoints
/// override the file's; with neither a file nor endpoints, a peer connects to
/// [`DEFAULT_ENDPOINT`] (retrying in the background until something listens there).
pub fn zenoh_config(
    file: Option<&Path>,
    connect: &[String],
    listen: &[String],
) -> Result<zenoh::Config> {
    let zerr = |e: zenoh::Error| Error::Zenoh(e.to_string());
    let mut config = match file {
        Some(path) => zenoh::Config::from_file(path)
            .map_err(|e| Error::Zenoh(format!("{}: {e}", path.display())))?,
        None => {
            let mut c = zenoh::Config::default();
            c.insert_json5("mode", r#""peer""#).map_err(zerr)?;
            c.insert_json5("scouting/multicast/enabled", "false")
                .map_err(zerr)?;
            // Timestamps on what this session publishes, as rmw_zenoh configures its sessions:
            // a zenoh-ext publisher with a cache (a latched topic) needs them.
            c.insert_json5("timestamping/enabled", "true")
                .map_err(zerr)?;
            // Multi-MB images arrive in many fragments: give each link room to reassemble them.
            c.insert_json5("transport/link/rx/buffer_size", "16777216")
                .map_err(zerr)?;
            if connect.is_empty() && listen.is_empty() {
                c.insert_json5("connect/endpoints", &format!(r#"["{DEFAULT_ENDPOINT}"]"#))
                    .map_err(zerr)?;
            }
            c
        }
    };
    let list = |v: &[String]| serde_json::to_string(v).unwrap_or_default();
    if !connect.is_empty() {
        config
            .insert_json5("connect/endpoints", &list(connect))
            .map_err(zerr)?;
    }
    if !listen.is_empty() {
        config
            .insert_json5("listen/endpoints", &list(listen))
            .map_err(zerr)?;
    }
    Ok(config)
}

/// Opens a session.
pub fn open(config: zenoh::Config) -> Result<zenoh::Session> {
    use zenoh::Wait;
    zenoh::open(config)
        .wait()
        .map_err(|e| Error::Zenoh(e.to_string()))
}
