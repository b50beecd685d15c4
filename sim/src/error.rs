//! The one error type of the simulator.

/// What can go wrong while simulating.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A publisher could not be declared on the Zenoh session.
    #[error("zenoh key {key}: {reason}")]
    Zenoh {
        /// The key expression.
        key: String,
        /// What Zenoh said.
        reason: String,
    },
    /// A stream thread could not be started.
    #[error("starting the thread for {topic}: {source}")]
    Thread {
        /// The topic the thread publishes.
        topic: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The rig lists a topic that is neither a camera nor an arm's joints or gripper.
    #[error("rig {rig}: topic {topic} belongs to no camera or arm")]
    UnknownTopic {
        /// The rig's name.
        rig: String,
        /// The topic.
        topic: String,
    },
    /// The rig could not be serialized into the episode's metadata.
    #[error("rig {rig}: {source}")]
    Rig {
        /// The rig's name.
        rig: String,
        /// What the TOML serializer said.
        source: toml::ser::Error,
    },
    /// A camera's video encoder could not be made.
    #[error("{0}")]
    Video(String),
    /// A simulator behind the bridge protocol failed (or could not be started).
    #[error("{what}: {reason}")]
    Bridge {
        /// What was being done (`metaworld/assembly: reset to seed 3`).
        what: String,
        /// What went wrong, with the bridge's own message where it gave one.
        reason: String,
    },
    /// Writing an episode failed.
    #[error(transparent)]
    Recorder(#[from] scaledp_recorder::Error),
}

/// The simulator's result type.
pub type Result<T> = std::result::Result<T, Error>;
