//! Bindings for `crate::allocation`: the separable allocation of a decoupled network.

use super::results::SeparableAllocation;
use super::{run_order, to_matrix};
use crate::allocation::separable_allocation as solve;
use crate::cost::CostOptions;
use crate::network::Network;
use crate::Result;
use numpy::{IntoPyArray, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;

/// The optimum of `Σ_i η_i(r_min + γ_i)` over `{γ ≥ 0, Σγ = σ}` for the subsystems
/// `(a_blocks[i], g_blocks[i], c_blocks[i])`, each with its one sensor (Newton with the diagonal
/// Hessian from the uniform start, at most `max_iter` steps, stopping at gap ≤ `tol`·value); with
/// `weight_blocks`, `η_i = tr(M_ii Σ_i)` (the diagonal blocks of an error weight `M`).
#[pyfunction]
#[pyo3(signature = (a_blocks, g_blocks, c_blocks, r_min, sigma, tol, max_iter, weight_blocks=None))]
#[allow(clippy::too_many_arguments)]
fn separable_allocation(
    py: Python<'_>,
    a_blocks: Vec<PyReadonlyArray2<'_, f64>>,
    g_blocks: Vec<PyReadonlyArray2<'_, f64>>,
    c_blocks: Vec<PyReadonlyArray2<'_, f64>>,
    r_min: f64,
    sigma: f64,
    tol: f64,
    max_iter: usize,
    weight_blocks: Option<Vec<PyReadonlyArray2<'_, f64>>>,
) -> PyResult<SeparableAllocation> {
    if a_blocks.len() != g_blocks.len() || a_blocks.len() != c_blocks.len() {
        return Err(crate::Error::Shape(format!(
            "a_blocks, g_blocks and c_blocks must have the same length, got {}, {}, {}",
            a_blocks.len(),
            g_blocks.len(),
            c_blocks.len()
        ))
        .into());
    }
    if weight_blocks
        .as_ref()
        .is_some_and(|w| w.len() != a_blocks.len())
    {
        return Err(
            crate::Error::Shape("weight_blocks must have one block per subsystem".into()).into(),
        );
    }
    let blocks: Vec<Network> = a_blocks
        .iter()
        .zip(&g_blocks)
        .zip(&c_blocks)
        .enumerate()
        .map(|(i, ((a, g), c))| {
            let net = Network::new(to_matrix(a), to_matrix(g), vec![to_matrix(c)])?;
            match &weight_blocks {
                Some(w) => net.with_error_weight(to_matrix(&w[i])),
                None => Ok(net),
            }
        })
        .collect::<Result<_>>()?;
    let order: usize = blocks.iter().map(Network::order).sum();
    let sol = run_order(py, order, || {
        solve(
            &blocks,
            r_min,
            sigma,
            tol,
            max_iter,
            &CostOptions::default(),
        )
    })?;
    Ok(SeparableAllocation {
        gamma: sol.gamma.into_pyarray(py).unbind(),
        value: sol.value,
        gap: sol.gap,
        iterations: sol.iterations,
    })
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(separable_allocation, m)?)?;
    Ok(())
}
