//! The integration tests in one executable (one link of the crate's dependencies instead of one per file). `s3` stays apart: it sets the process's AWS variables.

mod common;
mod errors;
mod guards;
mod hostile;
mod hostile_video;
mod images;
mod lerobot_video;
mod normalize;
mod order;
mod parts;
mod streaming;
mod video;
mod windows;
