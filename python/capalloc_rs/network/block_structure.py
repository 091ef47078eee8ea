"""The block description of the paper's networks: ``A = blockdiag(A_i) + ε·coupling`` with the
subsystems ``(A_i, G_i)`` and each sensor measuring ``c_iᵀ x_i`` of its own subsystem."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arrays import F64

__all__ = ["BlockStructure"]


@dataclass(frozen=True, eq=False)
class BlockStructure:
    """The block description of a network (the paper's model).

    Attributes:
        a_blocks: ``A_i`` (``n_i × n_i``).
        g_blocks: ``G_i`` (``n_i × m_i``).
        c_blocks: ``c_i`` (``n_i × p_i``): sensor ``i`` measures ``c_iᵀ x_i``.
        coupling: the ``n × n`` matrix of the couplings ``A_ij`` (zero diagonal blocks), *before*
            multiplication by ``eps``: ``A = blockdiag(A_i) + eps · coupling``.
        eps: the coupling strength ``ε``.
    """

    a_blocks: tuple[F64, ...]
    g_blocks: tuple[F64, ...]
    c_blocks: tuple[F64, ...]
    coupling: F64
    eps: float

    @property
    def sizes(self) -> tuple[int, ...]:
        """``(n_1, …, n_N)``."""
        return tuple(int(a.shape[0]) for a in self.a_blocks)

    @property
    def offsets(self) -> tuple[int, ...]:
        """Start of each block in the state vector, and ``n`` at the end."""
        return tuple(int(v) for v in np.concatenate([[0], np.cumsum(self.sizes)]))

    def block(self, i: int, j: int) -> F64:
        """The unscaled coupling block ``A_ij`` (``n_i × n_j``; zero when ``i == j``)."""
        o = self.offsets
        return self.coupling[o[i] : o[i + 1], o[j] : o[j + 1]]

    @property
    def couplings(self) -> dict[tuple[int, int], F64]:
        """The nonzero coupling blocks ``{(i, j): A_ij}`` (unscaled, ``i ≠ j``)."""
        nn = len(self.a_blocks)
        out: dict[tuple[int, int], F64] = {}
        for i in range(nn):
            for j in range(nn):
                if i != j:
                    b = self.block(i, j)
                    if np.any(b != 0):
                        out[(i, j)] = b
        return out

    def _equal(self, other: BlockStructure) -> bool:
        return (
            self.eps == other.eps
            and len(self.a_blocks) == len(other.a_blocks)
            and all(
                np.array_equal(x, y)
                for xs, ys in (
                    (self.a_blocks, other.a_blocks),
                    (self.g_blocks, other.g_blocks),
                    (self.c_blocks, other.c_blocks),
                )
                for x, y in zip(xs, ys, strict=True)
            )
            and np.array_equal(self.coupling, other.coupling)
        )
