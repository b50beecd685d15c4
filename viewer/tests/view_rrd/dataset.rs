//! A converted dataset: every stored frame once, its state and action, predicted chunks.

use super::*;

/// Per row of the first data file: (episode, frame, column values) for float list columns and
/// sha256 of image bytes.
fn data_rows(ds: &Path) -> Vec<BTreeMap<String, Value>> {
    use arrow_array::cast::AsArray;
    use arrow_array::Array;
    let file = std::fs::File::open(ds.join("data/chunk-000/file-000.parquet")).unwrap();
    let mut out = Vec::new();
    for batch in parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap()
    {
        let batch = batch.unwrap();
        for i in 0..batch.num_rows() {
            let mut row = BTreeMap::new();
            for (f, c) in batch.schema().fields().iter().zip(batch.columns()) {
                let v = match c.data_type() {
                    arrow_schema::DataType::Int64 => {
                        Value::from(c.as_primitive::<arrow_array::types::Int64Type>().value(i))
                    }
                    arrow_schema::DataType::FixedSizeList(..) => {
                        let l = c.as_fixed_size_list().value(i);
                        Value::from(
                            l.as_primitive::<arrow_array::types::Float32Type>()
                                .values()
                                .iter()
                                .map(|&x| f64::from(x))
                                .collect::<Vec<_>>(),
                        )
                    }
                    arrow_schema::DataType::Struct(_) => {
                        let b = c
                            .as_struct()
                            .column_by_name("bytes")
                            .unwrap()
                            .as_binary::<i32>()
                            .value(i)
                            .to_vec();
                        Value::from(b.len())
                    }
                    _ => continue,
                };
                row.insert(f.name().clone(), v);
            }
            out.push(row);
        }
    }
    out
}

#[test]
fn a_dataset_shows_every_stored_frame_once_and_its_state_and_action() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let inputs: Vec<PathBuf> = (0..2)
        .map(|k| {
            let p = dir.path().join(format!("episode_{k:06}.mcap"));
            synth(&p, &rig, k, 2.0);
            p
        })
        .collect();
    let ds = dir.path().join("ds");
    convert_dataset(&inputs, &ds);
    let out = dir.path().join("ds.rrd");
    let summary = save(&[&ds], ViewOptions::new(), &out);
    assert_eq!(summary.shown.len(), 2);
    let recs = read(&out);
    assert_eq!(recs.len(), 2);
    let stored = data_rows(&ds);
    for r in &recs {
        let ep: i64 = r["recording_id"]
            .as_str()
            .unwrap()
            .rsplit('#')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let mine: Vec<&BTreeMap<String, Value>> = stored
            .iter()
            .filter(|row| row["episode_index"] == ep)
            .collect();
        let n = mine.len() as i64;
        assert!(n > 10);
        for cam in ["front", "wrist"] {
            let path = format!("/cameras/{cam}");
            assert_eq!(
                image_times(r, &path, "frame_index"),
                (0..n).collect::<Vec<_>>(),
                "{path}: every stored frame once"
            );
            let mut by_frame = rows(r, &path);
            by_frame.sort_by_key(|row| row["frame_index"].as_i64());
            for (row, src) in by_frame.iter().zip(&mine) {
                assert_eq!(
                    row["EncodedImage:blob"]["bytes"],
                    src[&format!("observation.images.{cam}")],
                    "JPEG passed through"
                );
                assert_eq!(row["EncodedImage:media_type"], "image/jpeg");
            }
        }
        for (d, dim) in ["x", "y", "z", "roll", "pitch", "yaw", "gripper"]
            .iter()
            .enumerate()
        {
            let got = scalars(r, &format!("/pose/arm/{dim}"), "frame_index");
            assert_eq!(got.len() as i64, n, "{dim}");
            for ((f, v), src) in got.iter().zip(&mine) {
                assert_eq!(*f, src["frame_index"].as_i64().unwrap());
                let s = src["observation.state"][d].as_f64().unwrap();
                let a = src["action"][d].as_f64().unwrap();
                assert_eq!(v, &vec![s, a], "{dim} frame {f}");
            }
        }
        assert_eq!(
            rows(r, "/world/arm/chain").len() as i64,
            n,
            "3-D from observation.joints"
        );
        let text: Vec<String> = rows(r, "/log")
            .iter()
            .map(|r| r["TextLog:text"].as_str().unwrap().to_string())
            .collect();
        assert!(
            text.contains(&"task: stack the cubes".to_string()),
            "{text:?}"
        );
    }
    // One episode, downsampled.
    // One episode, downsampled, with a policy's chunks (4 steps of 7) at every other frame.
    let one = dir.path().join("one.rrd");
    let frames: Vec<i64> = (0..stored.iter().filter(|r| r["episode_index"] == 1).count() as i64)
        .step_by(2)
        .collect();
    let prediction = Prediction {
        frames: frames.clone(),
        values: (0..frames.len() * 4 * 7).map(|i| i as f32 * 1e-3).collect(),
    };
    let s = save(
        &[&ds],
        ViewOptions::new()
            .episodes(vec![1])
            .max_width(Some(32))
            .prediction(1, prediction.clone()),
        &one,
    );
    assert_eq!(s.shown.len(), 1);
    let recs = read(&one);
    assert_eq!(recs.len(), 1);
    assert!(recs[0]["recording_id"].as_str().unwrap().ends_with("#1"));
    let mut predicted = rows(&recs[0], "/world/arm/predicted_chunk");
    predicted.sort_by_key(|row| row["frame_index"].as_i64());
    let at: Vec<i64> = predicted
        .iter()
        .map(|row| row["frame_index"].as_i64().unwrap())
        .collect();
    assert_eq!(
        at, frames,
        "a predicted chunk at each predicted frame, once"
    );
    for row in &predicted {
        assert_eq!(
            row["LineStrips3D:strips"],
            serde_json::json!([4]),
            "C points"
        );
    }
    // Chunks that do not fit the dataset's 7 action dimensions: an error naming the dataset.
    let bad = Prediction {
        frames: vec![0, 1],
        values: vec![0.0; 2 * 4 * 5],
    };
    let err = scaledp_viewer::view(
        &[ds.to_string_lossy().to_string()],
        ViewOptions::new().episodes(vec![1]).prediction(1, bad),
        &Target::Save(dir.path().join("bad.rrd")),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("do not fit 7 action dimensions"), "{err}");
}
