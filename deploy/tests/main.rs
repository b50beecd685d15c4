//! The deploy crate against the simulated rig: alignment, the controller, eval, the image chain, serve.
//!
//! One test executable for the crate (each file a module): one link instead of one per file.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

mod alignment;
mod common;
mod controller;
mod eval;
mod image_chain;
mod serve;
