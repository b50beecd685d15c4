//! `scaledp convert` for the tests whose inputs carry no success or failure label (short
//! synthetic episodes, bags, foreign recordings) and which test something else than that
//! choice: [`scaledp_tests::convert_cli`] and [`scaledp_tests::convert_ok`] with
//! `--unlabeled keep` (`convert_labels` tests the choice itself).

use std::ffi::OsStr;
use std::process::Output;

/// The flags that keep unlabelled episodes.
pub const KEEP_UNLABELED: [&str; 2] = ["--unlabeled", "keep"];

fn with_keep<'a>(args: &[&'a OsStr]) -> Vec<&'a OsStr> {
    let mut a = args.to_vec();
    a.extend(KEEP_UNLABELED.map(OsStr::new));
    a
}

/// [`scaledp_tests::convert_cli`] keeping unlabelled episodes.
pub fn convert_cli(args: &[&OsStr]) -> Output {
    scaledp_tests::convert_cli(&with_keep(args))
}

/// [`scaledp_tests::convert_ok`] keeping unlabelled episodes.
pub fn convert_ok(args: &[&OsStr], converted: &str) -> String {
    scaledp_tests::convert_ok(&with_keep(args), converted)
}
