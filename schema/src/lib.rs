//! scaledp's shared vocabulary: the ROS 2 messages we record and convert (with CDR and their
//! `ros2msg` definitions), the rig description (arms, cameras, topics, rates), the episode
//! metadata contract, and pose math (forward kinematics, roll/pitch/yaw).
//!
//! No I/O framework, no networking: everything else in the workspace depends on this crate,
//! and it depends on nothing heavy.

pub mod action;
pub mod benchmarks;
mod cdr;
mod chains;
pub mod episode;
mod error;
mod fov;
pub mod kinematics;
pub mod msg;
pub mod rig;
mod simulator;

pub use action::ActionSpace;
pub use cdr::{CdrReader, CdrWriter, CDR_BE_HEADER, CDR_LE_HEADER};
pub use episode::{EpisodeMetadata, Label};
pub use error::{Error, Result};
pub use fov::{fov_label, FovChange};
pub use kinematics::RobotModel;
pub use msg::RosMessage;
pub use rig::Rig;
