//! The operators' labels of a job's inputs, read ahead of converting them, so a job that was
//! not told what to do with unlabelled episodes ([`crate::Unlabeled::Refuse`]) refuses before
//! it converts anything. An MCAP file's metadata records are read through its summary (the
//! footer, the summary section and the records themselves: a few kilobytes); an MCAP object's
//! the same way by range. Bags and rosbag2 directories carry no label. An MCAP input whose
//! label cannot be read this way (no summary, cut short) is left to the conversion, which
//! refuses that input alone.

use std::path::PathBuf;

use scaledp_schema::{EpisodeMetadata, Label};
use scaledp_store::Bucket;

use crate::inputs::is_mcap_file;
use crate::mcap_remote::RemoteMcap;
use crate::mcap_stream::Metadata;
use crate::objects::Input;
use crate::summary::local_metadata;

/// What is known ahead of an input's label.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ahead {
    /// Its recording says.
    Known(Label),
    /// It has no label: a bag, a rosbag2 directory, an MCAP file without our metadata.
    None,
    /// Not readable ahead: the conversion decides.
    Unknown,
}

/// The label in `records` (None: no episode record of ours, or no label in it).
fn label_in(records: &Metadata) -> Ahead {
    match EpisodeMetadata::from_records(records) {
        Some(Ok(m)) => m.label.map_or(Ahead::None, Ahead::Known),
        Some(Err(_)) => Ahead::Unknown,
        None => Ahead::None,
    }
}

/// What can be told ahead of `input`'s label.
pub(crate) fn label_ahead(input: &Input) -> Ahead {
    match input {
        Input::Local(path) if is_mcap_file(path) => match local_metadata(path) {
            Ok(Some(records)) => label_in(&records),
            _ => Ahead::Unknown,
        },
        Input::Local(_) => Ahead::None,
        Input::Object(o) => {
            let info = o.objects.first();
            match info.filter(|_| !o.directory && o.url.file_name().ends_with(".mcap")) {
                None => Ahead::None,
                Some(info) => {
                    let remote = Bucket::connect(&o.url.bucket)
                        .map_err(crate::error::Error::from)
                        .and_then(|b| RemoteMcap::open(b, info.clone()));
                    match remote.and_then(|r| r.metadata()) {
                        Ok(Some(records)) => label_in(&records),
                        _ => Ahead::Unknown,
                    }
                }
            }
        }
    }
}

/// The inputs known ahead to be unlabelled (recorded as `unlabeled`, or without a label).
pub(crate) fn unlabeled_inputs(inputs: &[Input]) -> Vec<PathBuf> {
    inputs
        .iter()
        .filter(|i| matches!(label_ahead(i), Ahead::None | Ahead::Known(Label::Unlabeled)))
        .map(Input::name)
        .collect()
}

/// The refusal of a job with unlabelled inputs, in one line: how many, which (the first 20),
/// and the two choices.
pub(crate) fn refusal(paths: &[PathBuf]) -> String {
    const SHOWN: usize = 20;
    let mut names: Vec<String> = paths
        .iter()
        .take(SHOWN)
        .map(|p| p.display().to_string())
        .collect();
    if paths.len() > SHOWN {
        names.push(format!("and {} more", paths.len() - SHOWN));
    }
    format!(
        "{} unlabelled episode{} (recorded without a success or failure label): {}; choose \
         --unlabeled keep (converted, labelled 'unlabeled') or --unlabeled skip (left out)",
        paths.len(),
        if paths.len() == 1 { "" } else { "s" },
        names.join(", ")
    )
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::fs::File;

    use super::*;

    #[test]
    fn the_refusal_names_at_most_twenty_inputs() {
        let one = refusal(&[PathBuf::from("demos/episode_000003.mcap")]);
        assert_eq!(
            one,
            "1 unlabelled episode (recorded without a success or failure label): \
             demos/episode_000003.mcap; choose --unlabeled keep (converted, labelled \
             'unlabeled') or --unlabeled skip (left out)"
        );
        let many: Vec<PathBuf> = (0..23)
            .map(|i| PathBuf::from(format!("e{i}.bag")))
            .collect();
        let line = refusal(&many);
        assert!(line.starts_with("23 unlabelled episodes ("), "{line}");
        assert!(line.contains("e19.bag, and 3 more;"), "{line}");
        assert!(!line.contains("e20.bag"), "{line}");
    }

    #[test]
    fn a_label_is_read_ahead_from_the_summary_alone() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, label: Option<Label>, summary: bool| {
            let path = dir.path().join(name);
            let file = std::io::BufWriter::new(File::create(&path).unwrap());
            let mut w = mcap::WriteOptions::new().create(file).unwrap();
            let meta = EpisodeMetadata {
                task: "t".into(),
                label,
                ..EpisodeMetadata::default()
            };
            w.write_metadata(&mcap::records::Metadata {
                name: scaledp_schema::episode::END_RECORD.into(),
                metadata: meta.end_record(),
            })
            .unwrap();
            w.finish().unwrap();
            drop(w);
            if !summary {
                // Cut short: no footer, no summary.
                let len = std::fs::metadata(&path).unwrap().len();
                let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
                f.set_len(len - 20).unwrap();
            }
            Input::Local(path)
        };
        let ok = write("a.mcap", Some(Label::Success), true);
        assert_eq!(label_ahead(&ok), Ahead::Known(Label::Success));
        let un = write("b.mcap", Some(Label::Unlabeled), true);
        assert_eq!(label_ahead(&un), Ahead::Known(Label::Unlabeled));
        let none = write("c.mcap", None, true);
        assert_eq!(label_ahead(&none), Ahead::None);
        let cut = write("d.mcap", Some(Label::Success), false);
        assert_eq!(label_ahead(&cut), Ahead::Unknown);
        let bag = dir.path().join("e.bag");
        std::fs::write(&bag, b"#ROSBAG V2.0\n").unwrap();
        assert_eq!(label_ahead(&Input::Local(bag.clone())), Ahead::None);
        let paths = unlabeled_inputs(&[ok, un, none, cut, Input::Local(bag)]);
        let names: Vec<String> = paths
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into())
            .collect();
        assert_eq!(names, ["b.mcap", "c.mcap", "e.bag"]);
    }
}
