"""The face Hessian of the path follower with Hessian-vector products (``face_hessian``): its solves
against the Hessian formed densely at the same point, the product ``η''·x`` it carries along the
conjugate gradients against a product asked of the network, the second solve at one point
(Galerkin start) and the limited-memory preconditioner against its defining identities; the
principal block of the Hessian (``BlockFace``) against the dense Hessian."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from capalloc_rs import Network
from capalloc_rs.allocation.face_hessian import BlockFace, ExactFace, KrylovFace, Reference
from capalloc_rs.errors import InvalidInputError


def _points(n: int = 30) -> tuple[Any, Any, Any]:
    """The network and two nearby evaluation points (the reference is formed at the first)."""
    net = Network.random(n, 2, eps=0.05, seed=3)
    r = np.full(n, net.r_min) + np.linspace(0.5, 2.0, n)
    return net, net.at(r), net.at(r * (1.0 + 1e-2 * np.cos(np.arange(n))))


def test_solves_and_carried_products_match_the_dense_hessian() -> None:
    net, p0, p1 = _points()
    ref = Reference()
    ref.form(p0)
    face = KrylovFace(p1, ref, fresh=False)
    jj = np.arange(0, 30, 2, dtype=np.intp)
    h = np.asarray(p1.hessian())
    block = 0.5 * (h[np.ix_(jj, jj)] + h[np.ix_(jj, jj)].T)
    b = np.sin(np.arange(jj.size) + 1.0)
    for x, hx, rhs in (
        (*face.tangent(jj, 1e-12), np.ones(jj.size)),
        (*face.solve(jj, b, 1e-12), b),  # the second solve: Galerkin start, deflated
    ):
        np.testing.assert_allclose(x, np.linalg.solve(block, rhs), rtol=1e-9)
        full = np.zeros(30)
        full[jj] = x
        direct = np.asarray(p1.hvp(full))
        np.testing.assert_allclose(hx, direct, atol=1e-10 * np.max(np.abs(direct)))
    # An enter: the tangent on a larger face starts from the solves made on the smaller one
    # at this point (embedded, 0 at the new sensors) and is the same.
    kk = np.arange(0, 30, dtype=np.intp)
    x_new, hx_new = face.tangent(kk, 1e-12)
    np.testing.assert_allclose(x_new, np.linalg.solve(0.5 * (h + h.T), np.ones(30)), rtol=1e-9)
    direct = np.asarray(p1.hvp(x_new))
    np.testing.assert_allclose(hx_new, direct, atol=1e-10 * np.max(np.abs(direct)))


def test_limited_memory_preconditioner_inverts_on_its_span_and_is_spd() -> None:
    rng = np.random.default_rng(7)
    n, k = 12, 4
    q = rng.standard_normal((n, n))
    a = q @ q.T + n * np.eye(n)  # "the Hessian"
    m = a + 0.3 * np.diag(rng.uniform(1.0, 3.0, n))  # "the reference", elsewhere
    ref = Reference()
    ref.h = m
    jj = np.arange(n, dtype=np.intp)
    s = rng.standard_normal((n, k))
    ref.update(jj, s, a @ s)
    pre = ref.preconditioner(jj)
    np.testing.assert_allclose(pre @ (a @ s), s, atol=1e-10)  # exact on the span of S
    np.testing.assert_allclose(pre, pre.T, atol=1e-14)
    assert np.min(np.linalg.eigvalsh(pre)) > 0.0
    # Orthogonal to S it is the reference's inverse, deflated: P M⁻¹ (P = I − S G⁻¹ (AS)ᵀ).
    w = np.linalg.svd(s.T)[2][k:].T  # w ⟂ S
    g = s.T @ a @ s
    proj = np.eye(n) - s @ np.linalg.solve(g, (a @ s).T)
    np.testing.assert_allclose(pre @ w, proj @ np.linalg.solve(m, w), atol=1e-10)
    # A degenerate span leaves the preconditioner as it was.
    ref.update(jj, np.column_stack([s[:, 0], s[:, 0]]), a @ np.column_stack([s[:, 0], s[:, 0]]))
    np.testing.assert_array_equal(ref.preconditioner(jj), pre)


def test_block_face_matches_the_full_hessian() -> None:
    # The principal block on the face and an entering sensor (|K| solves instead of N): its
    # entries, solves and carried products against the dense Hessian and products asked of
    # the network; a face outside the block extends it.
    net, _, p1 = _points(12)
    h = np.asarray(p1.hessian())
    idx = np.array([1, 4, 5, 9], dtype=np.intp)
    blk = np.asarray(p1.hessian_block([int(i) for i in idx]))
    np.testing.assert_allclose(blk, h[np.ix_(idx, idx)], rtol=1e-12, atol=0.0)
    face = BlockFace(p1, idx)
    jj = np.array([1, 5, 9], dtype=np.intp)
    b = np.cos(np.arange(jj.size) + 0.5)
    x, hx = face.solve(jj, b)
    np.testing.assert_allclose(x, np.linalg.solve(h[np.ix_(jj, jj)], b), rtol=1e-10)
    full = np.zeros(12)
    full[jj] = x
    direct = np.asarray(p1.hvp(full))
    scale = float(np.max(np.abs(direct)))
    np.testing.assert_allclose(hx[idx], direct[idx], atol=1e-12 * scale)
    assert np.all(np.isnan(np.delete(hx, idx)))  # not computed: filled in by complete()
    np.testing.assert_allclose(face.complete(jj, x, hx), direct, atol=1e-12 * scale)
    wide = np.array([0, 1, 5], dtype=np.intp)  # sensor 0 outside the block
    xw, _ = face.tangent(wide)
    np.testing.assert_allclose(xw, np.linalg.solve(h[np.ix_(wide, wide)], np.ones(3)), rtol=1e-10)
    assert face.dominant(jj) == bool(ExactFace(h).dominant(jj))


def test_hessian_block_refuses_bad_indices() -> None:
    _, _, p1 = _points(5)
    for bad in ([5], [-1], [0.5], "ab"):
        with pytest.raises(InvalidInputError, match="idx"):
            p1.hessian_block(bad)
    assert np.asarray(p1.hessian_block([])).shape == (0, 0)
