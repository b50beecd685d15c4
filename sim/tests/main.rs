//! The integration tests in one executable (one link of the crate's dependencies instead of one per file).

mod aloha;
mod bridge;
mod live;
mod record_convert;
mod record_rig;
mod record_session;
mod record_verdict;
