//! Helpers shared by scaledp's tests and benchmarks, each in one place: the workspace root, the
//! project's Python venvs and the `scaledp_data` wheel, free loopback ports, process figures
//! from /proc (CPU seconds, peak memory, load) with a measured child-process runner, the
//! ROS bag fixtures written by `rosbags`, and for object storage a loopback moto S3 server
//! ([`Moto`]) with a proxy that counts, records and breaks its traffic ([`Proxy`]).
//!
//! What the benchmarks call at run time returns [`Error`]s ([`free_port`], [`measure`],
//! [`Venv::python`], [`scaledp_data_wheel`], [`workspace_from_current_dir`]); the helpers only
//! tests call ([`python`], [`run_python`], [`free_endpoint`], [`make_bags`],
//! [`workspace_root`]) panic with a message saying what to run, a test's way of failing.

mod bags;
mod error;
mod moto;
mod net;
mod process;
mod proxy;
mod python;
mod workspace;

pub use bags::{make_bags, make_bags_lasting};
pub use error::{Error, Result};
pub use moto::Moto;
pub use net::{free_endpoint, free_port, loopback_endpoint};
pub use process::{cpu_seconds, cpu_seconds_at, load_average, measure, vm_hwm, Measured};
pub use proxy::{Hook, Proxy, ProxyState};
pub use python::{
    lerobot_video, python, run_python, scaledp_data_wheel, Venv, BENCH_VENV, TEST_VENV,
};
pub use workspace::{find_workspace, workspace_from_current_dir, workspace_root};
