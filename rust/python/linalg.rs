//! Bindings for `crate::linalg` and `crate::care`.

use super::results::{CareSolution, SchurForm, VanLoan};
use super::{run_order, to_matrix, to_numpy};
use crate::care::{generalized::solve_care_generalized, CareOptions};
use crate::linalg::{expm as expm_mod, schur::RealSchur, sylvester};
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;

type Arr<'py> = Bound<'py, PyArray2<f64>>;

// Signatures spell defaults as literals so that Python's text signatures (and `_core.pyi`, checked
// by stubtest) show the numbers; these assertions keep them equal to the core's constants.
const _: () = assert!(crate::care::DEFAULT_NEWTON_STEPS == 8);

/// The stabilising solution and its diagnostics ([`CareSolution`]) for `AᵀXE + EᵀXA − (EᵀXB + S) R⁻¹ (BᵀXE + Sᵀ) + Q = 0`; `r=None` means
/// `R = I`, `e=None` means `E = I`, `s=None` means `S = 0` (then this is
/// `AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0`).
#[pyfunction]
#[pyo3(signature = (a, b, q, r=None, e=None, s=None, scale=true, newton_steps=8, balance=true, accept_marginal=false))]
#[allow(clippy::too_many_arguments)]
fn care<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: Option<PyReadonlyArray2<'py, f64>>,
    e: Option<PyReadonlyArray2<'py, f64>>,
    s: Option<PyReadonlyArray2<'py, f64>>,
    scale: bool,
    newton_steps: usize,
    balance: bool,
    accept_marginal: bool,
) -> PyResult<CareSolution> {
    let (a, b, q) = (to_matrix(&a), to_matrix(&b), to_matrix(&q));
    let (r, e, s) = (
        r.as_ref().map(to_matrix),
        e.as_ref().map(to_matrix),
        s.as_ref().map(to_matrix),
    );
    let opts = CareOptions {
        scale,
        balance,
        newton_steps,
        accept_marginal,
    };
    let sol = run_order(py, a.nrows(), || {
        solve_care_generalized(&a, &b, &q, r.as_ref(), e.as_ref(), s.as_ref(), &opts)
    })?;
    Ok(CareSolution {
        x: to_numpy(py, sol.x).unbind(),
        residual: sol.residual,
        rcond: sol.rcond,
        closed_loop_abscissa: sol.closed_loop_abscissa,
        newton_steps: sol.newton_steps,
        scaling: sol.scaling,
        forward_error: sol.forward_error,
        trace_error: sol.trace_error,
        axis_margin: sol.axis_margin,
        marginal: sol.marginal,
    })
}

/// `A X + X Aᵀ = Q`.
#[pyfunction]
fn solve_lyapunov<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
) -> PyResult<Arr<'py>> {
    let (a, q) = (to_matrix(&a), to_matrix(&q));
    let x = run_order(py, a.nrows(), || sylvester::solve_lyapunov(&a, &q))?;
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
    let x = run_order(py, a.nrows().max(b.nrows()), || {
        sylvester::solve_sylvester(&a, &b, &q)
    })?;
    Ok(to_numpy(py, x))
}

/// Real Schur form ([`SchurForm`]); `sort` is `None`, `"lhp"` (Re λ < 0), `"rhp"` (Re λ ≥ 0),
/// `"iuc"` (|λ| ≤ 1) or `"ouc"` (|λ| > 1) — scipy's rules.
#[pyfunction]
#[pyo3(signature = (a, sort=None))]
fn schur<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    sort: Option<&str>,
) -> PyResult<SchurForm> {
    let select: Option<fn(f64, f64) -> bool> = match sort {
        None => None,
        Some("lhp") => Some(|re, _| re < 0.0),
        Some("rhp") => Some(|re, _| re >= 0.0),
        Some("iuc") => Some(|re, im| re.hypot(im) <= 1.0),
        Some("ouc") => Some(|re, im| re.hypot(im) > 1.0),
        Some(other) => {
            return Err(crate::Error::InvalidInput(format!(
                "sort must be None, 'lhp', 'rhp', 'iuc' or 'ouc', got {other:?}"
            ))
            .into())
        }
    };
    let a = to_matrix(&a);
    let (t, z, sdim) = run_order(py, a.nrows(), || -> crate::Result<_> {
        let mut s = RealSchur::new(&a)?;
        let sdim = match select {
            Some(f) => s.reorder(f)?,
            None => 0,
        };
        Ok((s.t, s.z, sdim))
    })?;
    Ok(SchurForm {
        t: to_numpy(py, t).unbind(),
        z: to_numpy(py, z).unbind(),
        sdim,
    })
}

/// Reorders a real Schur form `(T, Z)` (as returned by `schur`) so that the eigenvalues with
/// `select[j]` true come first (`j` in the order of the diagonal of `T`; a complex pair moves when
/// either of its entries is selected); returns the reordered [`SchurForm`].
#[pyfunction]
fn schur_reorder<'py>(
    py: Python<'py>,
    t: PyReadonlyArray2<'py, f64>,
    z: PyReadonlyArray2<'py, f64>,
    select: Vec<bool>,
) -> PyResult<SchurForm> {
    let (t, z) = (to_matrix(&t), to_matrix(&z));
    let (t, z, sdim) = run_order(py, t.nrows(), || -> crate::Result<_> {
        let mut s = RealSchur::from_parts(t, z)?;
        let sdim = s.reorder_selected(&select)?;
        Ok((s.t, s.z, sdim))
    })?;
    Ok(SchurForm {
        t: to_numpy(py, t).unbind(),
        z: to_numpy(py, z).unbind(),
        sdim,
    })
}

/// `e^A`.
#[pyfunction]
fn expm<'py>(py: Python<'py>, a: PyReadonlyArray2<'py, f64>) -> PyResult<Arr<'py>> {
    let a = to_matrix(&a);
    let e = run_order(py, a.nrows(), || expm_mod::expm(&a))?;
    Ok(to_numpy(py, e))
}

/// [`VanLoan`] `(e, h)` with `e = e^{At}`, `H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`.
#[pyfunction]
fn van_loan<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    t: f64,
) -> PyResult<VanLoan> {
    let (a, q) = (to_matrix(&a), to_matrix(&q));
    let vl = run_order(py, a.nrows(), || {
        crate::linalg::van_loan::van_loan(&a, &q, t)
    })?;
    Ok(VanLoan {
        e: to_numpy(py, vl.e).unbind(),
        h: to_numpy(py, vl.h).unbind(),
    })
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(care, m)?)?;
    m.add_function(wrap_pyfunction!(solve_lyapunov, m)?)?;
    m.add_function(wrap_pyfunction!(solve_sylvester, m)?)?;
    m.add_function(wrap_pyfunction!(schur, m)?)?;
    m.add_function(wrap_pyfunction!(schur_reorder, m)?)?;
    m.add_function(wrap_pyfunction!(expm, m)?)?;
    m.add_function(wrap_pyfunction!(van_loan, m)?)?;
    Ok(())
}
