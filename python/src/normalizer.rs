//! `scaledp_data.Normalizer`: the loader's state / action normalization on numpy arrays, so a
//! trainer can normalize inputs and un-normalize what its policy predicts.

use numpy::{AllowTypeChange, PyArrayLikeDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::convert::{array, norm_name};

/// The state and action normalizations of a loader (from the dataset's `meta/stats.json`).
/// Each method takes an array-like whose last axis is the state (or action) width and returns a
/// new float32 array of the same shape.
#[pyclass(module = "scaledp_data", frozen)]
pub struct Normalizer {
    pub(crate) inner: scaledp_datasets::Normalizer,
}

type Rows<'py> = PyArrayLikeDyn<'py, f32, AllowTypeChange>;

fn apply<'py>(
    py: Python<'py>,
    x: Rows<'py>,
    dim: usize,
    what: &str,
    f: impl Fn(&mut [f32]),
) -> PyResult<Bound<'py, PyAny>> {
    let shape = x.shape().to_vec();
    if shape.last() != Some(&dim) {
        return Err(PyValueError::new_err(format!(
            "{what}: the last axis must have the {dim} values of a row, the array has shape {shape:?}"
        )));
    }
    let mut v: Vec<f32> = x.as_array().iter().copied().collect();
    f(&mut v);
    array(py, v, shape)
}

#[pymethods]
impl Normalizer {
    /// Normalizes state rows (`[..., S]`).
    fn normalize_state<'py>(&self, py: Python<'py>, x: Rows<'py>) -> PyResult<Bound<'py, PyAny>> {
        let n = &self.inner;
        apply(py, x, n.state.dim(), "normalize_state", |v| {
            n.normalize_state(v)
        })
    }

    /// Un-normalizes state rows (`[..., S]`).
    fn unnormalize_state<'py>(&self, py: Python<'py>, x: Rows<'py>) -> PyResult<Bound<'py, PyAny>> {
        let n = &self.inner;
        apply(py, x, n.state.dim(), "unnormalize_state", |v| {
            n.unnormalize_state(v)
        })
    }

    /// Normalizes action rows (`[..., A]`).
    fn normalize_action<'py>(&self, py: Python<'py>, x: Rows<'py>) -> PyResult<Bound<'py, PyAny>> {
        let n = &self.inner;
        apply(py, x, n.action.dim(), "normalize_action", |v| {
            n.normalize_action(v)
        })
    }

    /// Un-normalizes action rows (`[..., A]`), e.g. a policy's predicted chunk.
    fn unnormalize_action<'py>(
        &self,
        py: Python<'py>,
        x: Rows<'py>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = &self.inner;
        apply(py, x, n.action.dim(), "unnormalize_action", |v| {
            n.unnormalize_action(v)
        })
    }

    /// State width, S.
    #[getter]
    fn state_dim(&self) -> usize {
        self.inner.state.dim()
    }

    /// Action width, A.
    #[getter]
    fn action_dim(&self) -> usize {
        self.inner.action.dim()
    }

    /// Per-dimension scale of the state: `normalized = raw · scale + offset` (float64, the
    /// numbers a checkpoint's `config.json` records).
    #[getter]
    fn state_scale(&self) -> Vec<f64> {
        self.inner.state.scale().to_vec()
    }

    /// Per-dimension offset of the state.
    #[getter]
    fn state_offset(&self) -> Vec<f64> {
        self.inner.state.offset().to_vec()
    }

    /// Per-dimension scale of the actions.
    #[getter]
    fn action_scale(&self) -> Vec<f64> {
        self.inner.action.scale().to_vec()
    }

    /// Per-dimension offset of the actions.
    #[getter]
    fn action_offset(&self) -> Vec<f64> {
        self.inner.action.offset().to_vec()
    }

    /// `"min_max"`, `"mean_std"` or `"none"`.
    #[getter]
    fn state_norm(&self) -> &'static str {
        norm_name(self.inner.state.norm)
    }

    /// `"min_max"`, `"mean_std"` or `"none"`.
    #[getter]
    fn action_norm(&self) -> &'static str {
        norm_name(self.inner.action.norm)
    }

    fn __repr__(&self) -> String {
        format!(
            "Normalizer(state: {} over {}, action: {} over {})",
            self.state_norm(),
            self.state_dim(),
            self.action_norm(),
            self.action_dim()
        )
    }
}
