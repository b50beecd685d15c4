//! The policy crate: the model, the numpy reference, the schedules, training.
//!
//! One test executable for the crate (each file a module): one link instead of one per file.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

mod common;
mod model;
mod numpy_reference;
mod schedule;
mod training;
