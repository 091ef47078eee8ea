//! Bindings for `crate::linalg` and `crate::care`.

use super::{run, to_matrix, to_numpy, to_pyerr};
use crate::care::{solve_care_weighted, CareOptions};
use crate::linalg::{expm as expm_mod, schur::RealSchur, sylvester};
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;

type Arr<'py> = Bound<'py, PyArray2<f64>>;

/// `(x, residual, rcond, closed_loop_abscissa, newton_steps, scaling)` for
/// `AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0`; `r=None` means `R = I`.
#[pyfunction]
#[pyo3(signature = (a, b, q, r=None, scale=true, newton_steps=0))]
#[allow(clippy::type_complexity)]
fn care<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: Option<PyReadonlyArray2<'py, f64>>,
    scale: bool,
    newton_steps: usize,
) -> PyResult<(Arr<'py>, f64, f64, f64, usize, f64)> {
    let (a, b, q) = (to_matrix(&a), to_matrix(&b), to_matrix(&q));
    let r = r.as_ref().map(to_matrix);
    let opts = CareOptions {
        scale,
        newton_steps,
    };
    let sol = run(py, || solve_care_weighted(&a, &b, &q, r.as_ref(), &opts))?;
    Ok((
        to_numpy(py, sol.x),
        sol.residual,
        sol.rcond,
        sol.closed_loop_abscissa,
        sol.newton_steps,
        sol.scaling,
    ))
}

/// `A X + X Aᵀ = Q`.
#[pyfunction]
fn solve_lyapunov<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
) -> PyResult<Arr<'py>> {
    let (a, q) = (to_matrix(&a), to_matrix(&q));
    let x = run(py, || sylvester::solve_lyapunov(&a, &q))?;
    Ok(to_numpy(py, x))
}

/// `A X + X B = Q`.
#[pyfunction]
fn solve_sylvester<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
) -> PyResult<Arr<'py>> {
    let (a, b, q) = (to_matrix(&a), to_matrix(&b), to_matrix(&q));
    let x = run(py, || sylvester::solve_sylvester(&a, &b, &q))?;
    Ok(to_numpy(py, x))
}

/// Real Schur form `(T, Z, sdim)`; `sort` is `None`, `"lhp"`, `"rhp"`, `"iuc"` or `"ouc"`.
#[pyfunction]
#[pyo3(signature = (a, sort=None))]
fn schur<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    sort: Option<&str>,
) -> PyResult<(Arr<'py>, Arr<'py>, usize)> {
    let select: Option<fn(f64, f64) -> bool> = match sort {
        None => None,
        Some("lhp") => Some(|re, _| re < 0.0),
        Some("rhp") => Some(|re, _| re > 0.0),
        Some("iuc") => Some(|re, im| re.hypot(im) <= 1.0),
        Some("ouc") => Some(|re, im| re.hypot(im) > 1.0),
        Some(other) => {
            return Err(to_pyerr(
                py,
                crate::Error::InvalidInput(format!(
                    "sort must be None, 'lhp', 'rhp', 'iuc' or 'ouc', got {other:?}"
                )),
            ))
        }
    };
    let a = to_matrix(&a);
    let (t, z, sdim) = run(py, || -> crate::Result<_> {
        let mut s = RealSchur::new(&a)?;
        let sdim = match select {
            Some(f) => s.reorder(f)?,
            None => 0,
        };
        Ok((s.t, s.z, sdim))
    })?;
    Ok((to_numpy(py, t), to_numpy(py, z), sdim))
}

/// `e^A`.
#[pyfunction]
fn expm<'py>(py: Python<'py>, a: PyReadonlyArray2<'py, f64>) -> PyResult<Arr<'py>> {
    let a = to_matrix(&a);
    let e = run(py, || expm_mod::expm(&a))?;
    Ok(to_numpy(py, e))
}

/// `(E, H)` with `E = e^{At}`, `H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`.
#[pyfunction]
fn van_loan<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    t: f64,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    let (a, q) = (to_matrix(&a), to_matrix(&q));
    let vl = run(py, || expm_mod::van_loan(&a, &q, t))?;
    Ok((to_numpy(py, vl.e), to_numpy(py, vl.h)))
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(care, m)?)?;
    m.add_function(wrap_pyfunction!(solve_lyapunov, m)?)?;
    m.add_function(wrap_pyfunction!(solve_sylvester, m)?)?;
    m.add_function(wrap_pyfunction!(schur, m)?)?;
    m.add_function(wrap_pyfunction!(expm, m)?)?;
    m.add_function(wrap_pyfunction!(van_loan, m)?)?;
    Ok(())
}
