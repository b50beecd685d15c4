//! The end-to-end and interop tests in one executable: each file below linked on its own held
//! every dependency of the workspace (zenoh, candle, arrow, rerun's SDK…), and 24 such links and
//! their repeated generic code were a large share of CI's release build. Each module still
//! reads alone; `cargo test -p scaledp-tests --test e2e -- record_e2e::` runs one.

mod aloha_e2e;
mod bench_record;
mod compressed_video;
mod convert_cluster;
mod convert_common;
mod convert_e2e;
mod convert_inputs;
mod convert_labels;
mod convert_outputs;
mod convert_resume;
mod convert_s3;
mod convert_s3_faults;
mod crash_recover;
mod cycle_cli;
mod depth;
mod fk_reference;
mod hostile_convert;
mod hostile_record;
mod layers;
mod load_demo;
mod metaworld_e2e;
mod python_module;
mod record_e2e;
mod record_more;
mod record_session;
mod record_topics;
mod record_topics_cli;
mod schema_interop;
mod torch_route;
mod video_output;
