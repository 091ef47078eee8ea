"""The one error seam between Rust and Python (``rust/python/errors.rs``).

The table below is the documented mapping (the doc comment of ``rust/python/errors.rs``), written
out here independently: the test compares it with the table the extension was built from, raises
every variant through the test hook, and triggers the reachable kinds through real bindings.
"""

from __future__ import annotations

import numpy as np
import pytest

from capalloc_rs import _core, errors

DOCUMENTED: dict[str, type[BaseException]] = {
    "Shape": errors.ShapeError,
    "NonFinite": errors.NonFiniteError,
    "InvalidInput": errors.InvalidInputError,
    "NoStabilizingSolution": errors.NoStabilizingSolutionError,
    "SingularProblem": errors.SingularProblemError,
    "Reorder": errors.ReorderError,
    "Convergence": errors.ConvergenceError,
    "Interrupted": KeyboardInterrupt,
}


def test_the_built_table_is_the_documented_one() -> None:
    built = dict(_core._core_error_mapping())
    assert built == {variant: cls.__name__ for variant, cls in DOCUMENTED.items()}


@pytest.mark.parametrize("variant", sorted(DOCUMENTED))
def test_every_variant_raises_its_class_with_its_message_unchanged(variant: str) -> None:
    message = f"{variant}: a message with ünïcode and {{braces}}"
    with pytest.raises(BaseException) as info:
        _core._raise_core_error(variant, message)
    assert type(info.value) is DOCUMENTED[variant]
    assert str(info.value) == message


@pytest.mark.parametrize(
    ("variant", "kind"),
    [("Shape", ValueError), ("NonFinite", ValueError), ("InvalidInput", ValueError)]
    + [
        (v, np.linalg.LinAlgError)
        for v in ("NoStabilizingSolution", "SingularProblem", "Reorder", "Convergence")
    ],
)
def test_input_errors_are_value_errors_and_failures_linalg_errors(
    variant: str, kind: type[Exception]
) -> None:
    with pytest.raises(kind) as info:
        _core._raise_core_error(variant, "m")
    assert isinstance(info.value, errors.CapallocError)


def test_unknown_variant_name_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown error variant"):
        _core._raise_core_error("NoSuchVariant", "m")


# -- the same classes through real bindings (no hook) --------------------------------------------


def test_shape_through_a_binding() -> None:
    with pytest.raises(errors.ShapeError):
        _core.solve_lyapunov(np.eye(2), np.eye(3))


def test_non_finite_through_a_binding() -> None:
    with pytest.raises(errors.NonFiniteError):
        _core.expm(np.array([[np.nan]]))


def test_invalid_input_through_a_binding() -> None:
    with pytest.raises(errors.InvalidInputError, match="sort must be"):
        _core.schur(np.eye(2), "sideways")


def test_singular_through_a_binding() -> None:
    # λ(A) + λ(B) = 1 + (−1) = 0: the Sylvester operator is singular.
    with pytest.raises(errors.SingularProblemError):
        _core.solve_sylvester(np.array([[1.0]]), np.array([[-1.0]]), np.array([[1.0]]))


def test_no_stabilizing_solution_through_a_binding() -> None:
    # Undamped oscillator, Q = 0: the unobservable modes ±i are Hamiltonian eigenvalues.
    a = np.array([[0.0, 1.0], [-1.0, 0.0]])
    b = np.array([[0.0], [1.0]])
    with pytest.raises(errors.NoStabilizingSolutionError, match="imaginary axis"):
        _core.care(a, b, np.zeros((2, 2)))


def test_no_convergence_through_a_binding() -> None:
    a, q, c = np.array([[-0.1]]), np.eye(1), [np.ones((1, 1))]
    slots = np.zeros(2, dtype=np.int64)
    with pytest.raises(errors.ConvergenceError):
        _core.SampledModel(a, q, c).fixed_point(1.0, slots, np.zeros((1, 1)), 1e-300, 1)


def test_one_name_per_error_on_both_sides() -> None:
    """The Python class of every core error is the Rust variant's name with ``Error`` appended
    (a cancellation is the built-in ``KeyboardInterrupt``)."""
    for variant, cls in _core._core_error_mapping():
        if variant != "Interrupted":
            assert cls == f"{variant}Error"
