//! Reading a dataset back: a row group of a data file (for `merge`), and the repair `open`
//! runs, which removes what a killed job may have left (files no episode lists, rows of an
//! episode that was never committed, temporary files).

use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;

use arrow_array::RecordBatch;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

use super::columns::{self, derr, read_row_group};
use super::meta::{self, data_path};
use super::videos::video_path;
use super::Dataset;
use crate::error::{Error, Result};

fn num_rows(path: &Path) -> Result<(u64, usize)> {
    let file = File::open(path).map_err(Error::io(path))?;
    let b = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| derr(path, e))?;
    let md = b.metadata();
    Ok((md.file_metadata().num_rows() as u64, md.num_row_groups()))
}

impl Dataset {
    /// Removes video files (and temporary ones) that no committed episode lists. A listed file
    /// may hold frames of an episode that was never committed at its end: readers go by each
    /// episode's span, and the next episode starts a new file.
    fn remove_unlisted_videos(&self) -> Result<()> {
        let videos = self.root.join("videos");
        if !videos.exists() {
            return Ok(());
        }
        let (cameras, spans): (Vec<String>, Vec<u64>) = match &self.sidecar {
            Some(s) => (
                s.cameras
                    .iter()
                    .map(|c| format!("observation.images.{c}"))
                    .collect(),
                s.episodes
                    .iter()
                    .filter_map(|e| e.video.as_ref().map(|v| v.file))
                    .collect(),
            ),
            None => (vec![], vec![]),
        };
        let mut files = Vec::new();
        for key in std::fs::read_dir(&videos)
            .map_err(Error::io(&videos))?
            .flatten()
        {
            for chunk in std::fs::read_dir(key.path())
                .into_iter()
                .flatten()
                .flatten()
            {
                files.extend(
                    std::fs::read_dir(chunk.path())
                        .into_iter()
                        .flatten()
                        .flatten()
                        .map(|f| f.path()),
                );
            }
        }
        for p in files {
            let known = cameras
                .iter()
                .any(|c| spans.iter().any(|&n| video_path(&self.root, c, n) == p));
            if !known {
                tracing::warn!(
                    "{}: not part of the dataset (left by a killed job); removed",
                    p.display()
                );
                std::fs::remove_file(&p).map_err(Error::io(&p))?;
            }
        }
        Ok(())
    }

    /// Removes temporary files, files no episode lists, and rows the record does not list.
    pub(super) fn repair(&mut self) -> Result<()> {
        let mut listed: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
        for e in self.episodes() {
            listed.entry(e.data_file).or_default().push(e.length);
        }
        let data = self.root.join("data");
        if data.exists() {
            for chunk in std::fs::read_dir(&data)
                .map_err(Error::io(&data))?
                .flatten()
            {
                for f in std::fs::read_dir(chunk.path())
                    .map_err(Error::io(chunk.path()))?
                    .flatten()
                {
                    let p = f.path();
                    let known = listed.keys().any(|&n| data_path(&self.root, n) == p);
                    if !known {
                        tracing::warn!(
                            "{}: not part of the dataset (left by a killed job); removed",
                            p.display()
                        );
                        std::fs::remove_file(&p).map_err(Error::io(&p))?;
                    }
                }
            }
        }
        self.remove_unlisted_videos()?;
        for (&file, lengths) in &listed {
            let path = data_path(&self.root, file);
            let (rows, groups) = num_rows(&path)?;
            let want: u64 = lengths.iter().sum();
            if rows == want && groups == lengths.len() {
                continue;
            }
            if groups < lengths.len() {
                return Err(derr(
                    &path,
                    format!(
                        "holds {groups} episodes but the record lists {}",
                        lengths.len()
                    ),
                ));
            }
            tracing::warn!(
                "{}: dropping rows of an episode that was never committed",
                path.display()
            );
            let keep: Vec<RecordBatch> = (0..lengths.len())
                .map(|g| read_row_group(&path, g))
                .collect::<Result<_>>()?;
            columns::write_parquet(&path, &keep)?;
        }
        if let Some(s) = &self.sidecar {
            let mut staged = columns::Staged::default();
            meta::stage_all(&self.root, s, self.file_size_mb, &mut staged)?;
            staged.commit()?;
        }
        for dir in [
            self.root.join("meta"),
            self.root.join("meta/episodes/chunk-000"),
        ] {
            for f in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
                if f.path().extension().is_some_and(|e| e == "tmp") {
                    let _ = std::fs::remove_file(f.path());
                }
            }
        }
        Ok(())
    }
}
