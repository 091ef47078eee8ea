"""The real-to-complex Schur conversion on degenerate 2×2 blocks (found by the property test of
``schur(output="complex")`` with subnormal entries: a block whose ``b`` underflowed to 0)."""

from __future__ import annotations

import numpy as np
import pytest

from capalloc_rs._complex_schur import real_to_complex


@pytest.mark.parametrize(
    "block",
    [
        [[2.0, 0.0], [3.0, 2.0]],  # b = 0: the double real eigenvalue 2
        [[1e-300, 0.0], [5e-309, 1e-300]],  # subnormal c
        [[0.5, 4e-309], [-3e-309, 0.5]],  # a genuine pair with subnormal b, c
        [[1.0, 1e300], [-1e-300, 1.0]],  # a badly scaled pair
    ],
)
def test_block_becomes_triangular_and_similar(block: list[list[float]]) -> None:
    t_real = np.array(block)
    z_real = np.eye(2)
    t, z = real_to_complex(t_real, z_real)
    assert t[1, 0] == 0.0 and np.all(np.isfinite(t)) and np.all(np.isfinite(z))
    np.testing.assert_allclose(z.conj().T @ z, np.eye(2), atol=1e-15)
    back = z @ t @ z.conj().T
    scale = np.abs(t_real).max()
    np.testing.assert_allclose(back, t_real, atol=1e-14 * scale, rtol=0)
