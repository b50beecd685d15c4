//! `scaledp_data`: the scaledp loader ([`scaledp_datasets`]) as a Python extension module.
//! `scaledp_data.Loader(...)` iterates dicts of numpy arrays that own the Rust batch buffers
//! (no copy), with the GIL released while a batch is awaited; `scaledp_data.torch` (pure
//! Python, in `python/scaledp_data/`) wraps it as a `torch.utils.data.IterableDataset`.

mod convert;
mod loader;
mod normalizer;

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    scaledp_data,
    DatasetError,
    PyRuntimeError,
    "A dataset could not be read (bad files, undecodable images, storage errors)."
);

/// A Rust loader error as the Python exception that fits it, with the Rust message (which
/// names the file and what is wrong).
pub(crate) fn to_py(e: scaledp_datasets::Error) -> PyErr {
    use scaledp_datasets::Error as E;
    let msg = e.to_string();
    match &e {
        E::Options(_) => PyValueError::new_err(msg),
        E::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(msg)
        }
        E::Io { .. } => PyOSError::new_err(msg),
        _ => DatasetError::new_err(msg),
    }
}

/// The extension module `scaledp_data._native` (re-exported by `scaledp_data`).
#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<loader::Loader>()?;
    m.add_class::<normalizer::Normalizer>()?;
    m.add("DatasetError", m.py().get_type::<DatasetError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
