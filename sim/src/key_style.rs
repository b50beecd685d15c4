//! How a simulated rig's topics map to Zenoh keys.

/// How topics map to Zenoh keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KeyStyle {
    /// zenoh-bridge-ros2dds: `zed/zed_node/...`, no attachment.
    #[default]
    Bridge,
    /// rmw_zenoh (Humble): `0/<topic>/<pkg::msg::dds_::T_>/TypeHashNotSupported` with attachments.
    Rmw,
}
