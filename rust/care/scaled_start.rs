//! A stabilising start for the closed-loop route from the same problem with a dearer input.
//!
//! When `G` is large against the rest of the data (a cheap input: `R = 1e-12` with one input,
//! `‖G‖ ~ 1e12`), the Hamiltonian's stable subspace can be computed without a single correct digit
//! of `X` (its forward-error bound says so) while the closed loop is perfectly usable. The same
//! problem with the input made `s` times dearer, `G/s` (`R·s`), is solved accurately by the
//! Hamiltonian route once `s` is large enough, and its stabilising solution `X_s` gives a
//! stabilising start for the real one: LQR's infinite upward gain margin. With
//! `A_s = A − (G/s)X_s` Hurwitz and `A_sᵀX_s + X_sA_s = −Q − X_s(G/s)X_s`, the closed loop of the
//! real problem, `A − GX_s = A − s·(G/s)X_s`, satisfies
//! `(A − GX_s)ᵀX_s + X_s(A − GX_s) = −Q − (2s − 1)·X_s(G/s)X_s ⪯ 0`,
//! so it is stable for every `s ≥ ½` (with `(Q, A)` detectable), however large `s` is. From there
//! Newton's iteration converges to the stabilising solution of the real problem: early steps
//! halve the excess, the last ones are quadratic (10–16 steps for a factor 1e3–1e8 on the cases
//! of `tests/test_care_closed_loop.py`).
//!
//! A start `s` times too dear multiplies its own error by `s` in the gain, and the dearer
//! problem's Hamiltonian solution may itself need a large `s` before it has digits (one case:
//! bounds 6e5, 8e2, 4e-2, 5e-3 at `s = 1e3, 1e6, 1e9, 1e12`). So the solution is carried down a
//! ladder of factors `1e3` apart: the Hamiltonian solution of the cheapest rung of [`FACTORS`]
//! with two digits, polished by Newton on its own problem, then Newton on each cheaper rung from
//! the previous rung's solution (each start stabilising by the margin above). The last rung, the
//! real problem, is the closed-loop route's (module `kleinman`); every iterate's closed loop is
//! checked by its computed spectrum as always.

use super::closed_loop_newton::newton_from;
use super::hamiltonian::hamiltonian_route;
use super::quadratic::Quadratic;
use super::CareOptions;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// The dearer inputs tried, cheapest first.
const FACTORS: [f64; 4] = [1e3, 1e6, 1e9, 1e12];

/// A rung's Hamiltonian solution starts the ladder when its own bound is at most this.
const START_BOUND: f64 = 1e-2;

/// A stabilising approximation of the solution with `G` from those with `G/s` (and the factor
/// `B/√s`), `s` down the ladder of [`FACTORS`]; `None` when no rung's Hamiltonian solution has
/// two digits or a Newton iteration on the way down fails.
pub(super) fn dearer_input_start(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<Option<DMatrix<f64>>> {
    let scaled = |s: f64| (g / s, factor.map(|b| b / s.sqrt()));
    let mut found = None;
    for (rung, &s) in FACTORS.iter().enumerate() {
        crate::cancel::check("the dearer-input start of the Riccati solver")?;
        let (gs, fs) = scaled(s);
        let mut not_lagrangian = false;
        match hamiltonian_route(a, &gs, fs.as_ref(), q, opts, &mut not_lagrangian) {
            Ok(sol) if sol.forward_error <= START_BOUND && !sol.marginal => {
                found = Some((rung, sol.x));
                break;
            }
            Err(Error::Interrupted(m)) => return Err(Error::Interrupted(m)),
            _ => {}
        }
    }
    let Some((rung, mut x)) = found else {
        return Ok(None);
    };
    for &s in FACTORS[..=rung].iter().rev() {
        let (gs, fs) = scaled(s);
        let quad = match &fs {
            Some(b) => Quadratic::Factor(b),
            None => Quadratic::Dense(&gs),
        };
        match newton_from(a, quad, q, x)? {
            Some((next, _)) => x = next,
            None => return Ok(None),
        }
    }
    Ok(Some(x))
}
