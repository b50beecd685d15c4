//! The `scaledp` command line. See `scaledp --help`; exit codes are listed in `cli.rs`.

fn main() -> std::process::ExitCode {
    scaledp::run()
}
