//! numpy ↔ flat `Vec<f64>` conversions shared by the bindings.

use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods, ndarray::ArrayD, ndarray::IxDyn};
use pyo3::prelude::*;

/// An array of `N`-vectors (shape `(..., N)`) as row-major values and the leading shape.
pub struct Vectors<const N: usize> {
    pub values: Vec<f64>,
    pub lead_shape: Vec<usize>,
}

impl<const N: usize> Vectors<N> {
    /// Reads any array-like of shape `(..., N)` (lists, integer or float32 arrays: converted to
    /// float64 by numpy). `what` names the argument in the error.
    pub fn extract(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Self> {
        let np = obj.py().import("numpy")?;
        let arr = np.call_method1("ascontiguousarray", (obj, "float64"))?;
        let arr = arr.cast_into::<PyArrayDyn<f64>>().map_err(|e| crate::value_error(format!("{what}: {e}")))?;
        let shape = arr.shape().to_vec();
        if shape.last() != Some(&N) {
            return Err(crate::value_error(format!("{what}: expected an array of shape (..., {N}), got {shape:?}")));
        }
        let values = arr.readonly().as_slice()?.to_vec();
        Ok(Vectors { values, lead_shape: shape[..shape.len() - 1].to_vec() })
    }

    /// The number of vectors.
    pub fn len(&self) -> usize {
        self.values.len() / N
    }

    /// The `i`-th vector.
    pub fn get(&self, i: usize) -> [f64; N] {
        std::array::from_fn(|k| self.values[i * N + k])
    }
}

/// `values` (row-major) as a float64 array of shape `lead_shape + (m,)`.
pub fn shaped<'py>(
    py: Python<'py>,
    values: Vec<f64>,
    lead_shape: &[usize],
    m: usize,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let mut shape = lead_shape.to_vec();
    shape.push(m);
    let arr = ArrayD::from_shape_vec(IxDyn(&shape), values).map_err(|e| crate::value_error(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// Rows of `M` values as an `(n, M)` float64 array.
pub fn rows<'py, const M: usize>(py: Python<'py>, rows: &[[f64; M]]) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    shaped(py, rows.iter().flatten().copied().collect(), &[rows.len()], M)
}
