//! The integration tests in one executable (one link of the crate's dependencies instead of one per file).

mod view_rrd;
