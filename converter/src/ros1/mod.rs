//! ROS 1 input: bags in format 2.0 ([`read_ros1_bag`]) and the ROS 1 serialization of the
//! message types the converter uses ([`decode`]).

mod bag;
pub mod decode;
mod record;
#[cfg(test)]
mod tests;

pub use bag::read_ros1_bag;
