"""The ``capalloc`` command line.

Subcommands (``capalloc`` alone prints them, with status 0; ``capalloc COMMAND --help`` every
option, each with its help)::

    capalloc demo [--plot FILE] [--tau T]                    the main job on a built-in network
    capalloc check MODEL                                     the network's assumptions
    capalloc solve MODEL --r-tot R [--method M] [--hessian H] [--integer]  optimum + certificate
        (--integer: --method greedy|branch-and-bound, --time-limit S, --max-nodes N)
    capalloc trace MODEL --sigma-max S [--plot FILE [--rates] [--log] [--budget]]  filtration
    capalloc schedule MODEL --tau T --r-tot R [--no-check]   best schedule at a finite period
    capalloc simulate MODEL --tau T (--r-tot R | --schedule 0,1,0,2) [--periods P] [--no-check]
    capalloc sweep SPEC --out DIR [--resume | --overwrite] [--workers K | --scheduler ADDRESS]

``--plot FILE`` needs matplotlib: without it the command fails (status 2) with the pip command; no
command writes a file that was not asked for. ``--no-check`` skips the check of Proposition 1 (as
``check=False`` does in the API) and says so in one line ``capalloc: warning: …`` on stderr. Slot
counts (``--r-tot`` of ``schedule``, ``simulate`` and ``solve --integer``) are integers (``8.0`` is
accepted); JSON output has integers for counts, slots, seeds and sensor indices.

MODEL is a network file (TOML, JSON or ``.npz``; see :mod:`capalloc_rs.model_io`), SPEC a sweep spec
(see :func:`capalloc_rs.sweep.load_spec`). Every subcommand takes ``--json`` for machine-readable
output on stdout: the result's ``to_dict()``, whose keys a sweep's rows have too. User mistakes (bad
files, bad arguments, infeasible or unsolvable problems) end with one line ``capalloc: error: …`` on
stderr and exit status 2, never a traceback (set ``CAPALLOC_TRACEBACK=1`` to see one); under
``--json`` the error is also printed on stdout as ``{"error": {"type": …, "message": …}}``. An
interrupted command (Ctrl-C) exits with status 130 and one line; a closed stdout pipe (``capalloc
demo | head -2``) ends quietly with status 0. ``trace``, ``schedule`` and ``simulate`` take
``--time-limit SECONDS`` (for ``simulate`` the whole command: the schedule search of ``--r-tot`` and
the Monte Carlo), ``trace`` and ``schedule`` also ``--max-nodes N`` / ``--max-moves N``; a budget
that ends the work early is not an error (exit status 0): the output says ``converged: False``,
which budget ``stopped`` it, and one ``stopped early (…)`` line with what the result then is. They
show progress on stderr when it is a terminal (``--no-progress``: none). ``solve --integer`` takes
``--time-limit`` too, and ``--max-nodes`` with ``--method branch-and-bound``: a stopped search
prints its best counts with their proven gap and ``stopped early (…)``, exit status 0.

Modules: :mod:`~capalloc_rs.cli.parser` (subcommands and options), one module per group of
commands (:mod:`~capalloc_rs.cli.demo`, :mod:`~capalloc_rs.cli.allocation` for check/solve/trace,
:mod:`~capalloc_rs.cli.sampled` for schedule/simulate, :mod:`~capalloc_rs.cli.sweep`),
:mod:`~capalloc_rs.cli.output` (printing), :mod:`~capalloc_rs.cli.errors` (exit statuses, the
one-line error, warnings) and :mod:`~capalloc_rs.cli.main` (the entry point).
"""

from __future__ import annotations

from .demo import demo_network
from .main import main
from .parser import build_parser

__all__ = ["main", "build_parser", "demo_network"]
