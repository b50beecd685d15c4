//! Training (work in progress).
pub(crate) mod optim;
