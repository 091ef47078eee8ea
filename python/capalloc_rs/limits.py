"""Limits on the work and input size that capalloc_rs accepts, checked before the work starts.

Each limit is a module-level constant: to raise one, assign to it before the call, e.g.
``capalloc_rs.limits.MAX_MODEL_STATES = 5000`` (the functions read the module attribute at call
time). Exceeding a limit raises :class:`~capalloc_rs.errors.InvalidInputError` (or
:class:`~capalloc_rs.errors.ModelFormatError` for model files,
:class:`~capalloc_rs.errors.SweepError` for sweep specs) naming the argument, its value and the
constant to change. The limits are far above anything the methods are meant for (their cost grows
like ``n³`` per evaluation); they exist so that a typo or a hostile file gives an error message at
once instead of an hour of work, a MemoryError or a hang.
"""

from __future__ import annotations

__all__ = [
    "MAX_MODEL_FILE_BYTES",
    "MAX_MODEL_STATES",
    "MAX_MODEL_ARRAY_ELEMENTS",
    "MAX_MODEL_ELEMENTS",
    "MAX_NPZ_MEMBERS",
    "MAX_NESTING",
    "MAX_ARRAYS",
    "MAX_NUMBER_CHARS",
    "MAX_INTEGER",
    "MAX_MONTE_CARLO_STEPS",
    "MAX_MONTE_CARLO_ELEMENTS",
    "MAX_INTEGER_ALLOCATION_SLOTS",
    "MAX_SCHEDULE_SLOTS",
    "MAX_SWEEP_TASKS",
    "MAX_SWEEP_WORKERS",
]

# -- Python side: model files, sweep specs, Monte Carlo, sweeps ---------------------------------

#: Largest TOML/JSON model or sweep-spec file read (bytes).
MAX_MODEL_FILE_BYTES = 256 * 2**20

#: Largest state dimension ``n`` (and any other array dimension) of a model file, and of
#: ``N·n`` for the random networks of a sweep spec. Checked on the declared shapes (the ``.npy``
#: headers of an ``.npz``) before any data are read.
MAX_MODEL_STATES = 2000

#: Most elements of one array of a model file (declared shape, before reading).
MAX_MODEL_ARRAY_ELEMENTS = MAX_MODEL_STATES * MAX_MODEL_STATES

#: Most elements of all arrays of a model file together (declared shapes, before reading); also
#: bounds the uncompressed size of an ``.npz`` (8 bytes per element plus headers), read from the
#: zip directory before anything is decompressed.
MAX_MODEL_ELEMENTS = 4 * MAX_MODEL_STATES * MAX_MODEL_STATES

#: Most members of an ``.npz`` model archive.
MAX_NPZ_MEMBERS = 10_000

#: Deepest nesting of arrays/tables in a TOML or JSON file (the schemas need at most 5).
MAX_NESTING = 64

#: Most arrays and tables (``[`` and ``{``, counted in the text) of a TOML or JSON file; a model
#: has a few per matrix row.
MAX_ARRAYS = 10**6

#: Longest number literal in a TOML or JSON file (characters).
MAX_NUMBER_CHARS = 100

#: Largest magnitude of an integer in a TOML or JSON file (a float64 holds integers exactly up to
#: 2⁵³; this bound only keeps numbers convertible).
MAX_INTEGER = 2**63

#: Most simulated steps ``runs × periods × slots per period`` of one Monte Carlo call.
MAX_MONTE_CARLO_STEPS = 10**9

#: Most state values held at once by one Monte Carlo call, ``runs × (n + slots per period)``
#: (each is 8 bytes, and a few arrays of this size are alive at a time).
MAX_MONTE_CARLO_ELEMENTS = 5 * 10**7

#: Largest ``r_tot`` of :func:`~capalloc_rs.allocation.integer_allocation` (slots).
MAX_INTEGER_ALLOCATION_SLOTS = 10**9

#: Most slots per period of a schedule (``r_tot`` of the schedule functions).
MAX_SCHEDULE_SLOTS = 10**6

#: Most tasks (networks × capacities) of one sweep.
MAX_SWEEP_TASKS = 10**8

#: Most local worker processes of one sweep.
MAX_SWEEP_WORKERS = 1024
