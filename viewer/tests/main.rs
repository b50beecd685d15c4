//! The integration tests in one executable (one link of the crate's dependencies instead of one per file).

mod depth_tf;
mod view_rrd;
