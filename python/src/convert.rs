//! Python values ↔ loader types: option strings, batches as dicts of numpy arrays, the
//! dataset info as a dict.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{Element, PyArray1, PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use scaledp_datasets::{Batch, DatasetInfo, DepthBatch, ImagePool, Norm, Split};

/// `"train" | "val" | "all"`.
pub fn split(s: &str) -> PyResult<Split> {
    match s {
        "train" => Ok(Split::Train),
        "val" => Ok(Split::Val),
        "all" => Ok(Split::All),
        _ => Err(PyValueError::new_err(format!(
            "split {s:?}: expected \"train\", \"val\" or \"all\""
        ))),
    }
}

/// `"min_max" | "mean_std" | "none"`.
pub fn norm(what: &str, s: &str) -> PyResult<Norm> {
    match s {
        "min_max" => Ok(Norm::MinMax),
        "mean_std" => Ok(Norm::MeanStd),
        "none" => Ok(Norm::None),
        _ => Err(PyValueError::new_err(format!(
            "{what} {s:?}: expected \"min_max\", \"mean_std\" or \"none\""
        ))),
    }
}

/// The Python name of a normalization.
pub fn norm_name(n: Norm) -> &'static str {
    match n {
        Norm::MinMax => "min_max",
        Norm::MeanStd => "mean_std",
        Norm::None => "none",
    }
}

/// Moves `v` into a numpy array of `shape` (the array owns the Vec's buffer: no copy).
pub fn array<'py, T: Element>(
    py: Python<'py>,
    v: Vec<T>,
    shape: Vec<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
}

/// The owner of a batch's image buffer while numpy arrays view it; when the last of them is
/// freed, the buffer goes back to the loader's [`ImagePool`] instead of to the allocator, so the
/// next batch reuses its pages (fresh pages for every 88 MB batch cost ~12 % of the loader).
#[pyclass(frozen, module = "scaledp_data")]
struct ImageBuffer {
    array: ArrayD<u8>,
    pool: ImagePool,
}

impl Drop for ImageBuffer {
    fn drop(&mut self) {
        let (v, _) = std::mem::take(&mut self.array).into_raw_vec_and_offset();
        self.pool.put(v);
    }
}

/// `images` as a numpy array of `shape` viewing the buffer in place (no copy), owned by an
/// [`ImageBuffer`] that hands it back to `pool` once Python frees it.
fn image_array<'py>(
    py: Python<'py>,
    images: Vec<u8>,
    shape: Vec<usize>,
    pool: ImagePool,
) -> PyResult<Bound<'py, PyAny>> {
    let array = ArrayD::from_shape_vec(IxDyn(&shape), images)
        .map_err(|e| PyValueError::new_err(format!("batch images: {e}")))?;
    let owner = Bound::new(py, ImageBuffer { array, pool })?;
    let view = &owner.get().array;
    // SAFETY: `owner` becomes the array's base object, so it lives as long as the array; and the
    // ImageBuffer is frozen (no Python or Rust code gets `&mut` to it before its Drop), so the
    // buffer is never reallocated while the array views it.
    #[allow(unsafe_code)]
    let a = unsafe { PyArrayDyn::borrow_from_array(view, owner.clone().into_any()) };
    Ok(a.into_any())
}

/// A batch as the dict a training loop reads; every buffer moves into its array (images into
/// one whose buffer returns to `pool` when freed).
pub fn batch_dict(
    py: Python<'_>,
    b: Batch,
    depth: Option<DepthBatch>,
    pool: ImagePool,
) -> PyResult<Bound<'_, PyDict>> {
    let (n, to, c) = (b.len, b.obs_horizon, b.action_chunk);
    let (h, w) = (b.height as usize, b.width as usize);
    let d = PyDict::new(py);
    d.set_item(
        "observation.images",
        image_array(py, b.images, vec![n, to, b.cameras.len(), 3, h, w], pool)?,
    )?;
    d.set_item(
        "observation.state",
        array(py, b.state, vec![n, to, b.state_dim])?,
    )?;
    d.set_item("action", array(py, b.action, vec![n, c, b.action_dim])?)?;
    d.set_item("obs_is_pad", array(py, b.obs_is_pad, vec![n, to])?)?;
    d.set_item("action_is_pad", array(py, b.action_is_pad, vec![n, c])?)?;
    d.set_item("episode_index", array(py, b.episode_index, vec![n])?)?;
    d.set_item("frame_index", array(py, b.frame_index, vec![n])?)?;
    if let Some(depth) = depth {
        let (dh, dw) = (depth.height as usize, depth.width as usize);
        let shape = vec![n, to, depth.cameras.len(), dh, dw];
        d.set_item("observation.depth", array(py, depth.values, shape)?)?;
    }
    Ok(d)
}

/// A JSON value as the Python value `json.loads` would give.
fn json<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::types::{PyList, PyNone};
    use pyo3::IntoPyObjectExt;
    Ok(match v {
        serde_json::Value::Null => PyNone::get(py).to_owned().into_any(),
        serde_json::Value::Bool(b) => b.into_bound_py_any(py)?,
        serde_json::Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) => i.into_bound_py_any(py)?,
            (None, Some(f)) => f.into_bound_py_any(py)?,
            _ => n.to_string().into_bound_py_any(py)?,
        },
        serde_json::Value::String(s) => s.into_bound_py_any(py)?,
        serde_json::Value::Array(a) => {
            let items = a
                .iter()
                .map(|x| json(py, x))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        serde_json::Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// What the loader reads, as a dict.
pub fn info_dict<'py>(py: Python<'py>, i: &DatasetInfo) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("location", &i.location)?;
    d.set_item("fps", i.fps)?;
    d.set_item("cameras", &i.cameras)?;
    d.set_item("image_size", (i.width, i.height))?;
    d.set_item("state_names", &i.state_names)?;
    d.set_item("action_names", &i.action_names)?;
    d.set_item("episodes", &i.episodes)?;
    d.set_item("frames", i.frames)?;
    d.set_item("total_episodes", i.total_episodes)?;
    d.set_item("depth_cameras", &i.depth_cameras)?;
    d.set_item("depth_units", &i.depth_units)?;
    d.set_item(
        "intrinsics",
        json(py, &serde_json::Value::Object(i.sensors.clone()))?,
    )?;
    Ok(d)
}
