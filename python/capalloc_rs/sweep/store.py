"""A sweep's output directory: Parquet part-files, the manifest, atomic writes, reading back.

``DIR/_sweep.json`` (the manifest) records what the sweep computes (``compute``, ``params``) and
its identity ``sweep_id``; each finished chunk is one part-file ``DIR/part-*.parquet`` carrying
that identity in its metadata, written atomically (a temporary file, flushed and fsynced, then
renamed). A part-file is accepted only if its schema is the sweep's, its identity the manifest's,
and every task id the one its row's network index, capacity and digest give under the manifest's
compute and parameters; otherwise it is refused with a :class:`~capalloc_rs.errors.SweepError`,
never merged. Temporary files of interrupted writes are removed when their owner is this process
or a dead process of this host (see :mod:`capalloc_rs.sweep.dirlock`).
"""

from __future__ import annotations

import contextlib
import json
import os
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import SweepError
from .columns import arrow, schema
from .dirlock import is_dead_debris, tmp_name
from .task_ids import task_id

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "FORMAT_VERSION",
    "MANIFEST",
    "PART_GLOB",
    "SWEEP_ID",
    "finish",
    "prepare_out",
    "read_parts",
    "read_results",
    "write_part",
]

MANIFEST = "_sweep.json"
#: The manifest key (and part-file metadata key) of a sweep's identity.
SWEEP_ID = "sweep_id"
#: The part-files of a sweep's directory.
PART_GLOB = "part-*.parquet"
_TMP_PREFIX = ".tmp-part-"
#: The id columns of a part-file, from which its task ids are re-derived.
_ID_COLUMNS = ["task_id", "network_index", "r_tot", "network_digest"]


#: The version of the output format. 2: the columns are named by the results' ``to_dict()`` keys
#: (1, before: ``gap``, ``kkt_residual``, ``relative_error``, and fewer columns).
FORMAT_VERSION = 2


def _manifest(compute: str, params: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "format": "capalloc-sweep-output",
        "version": FORMAT_VERSION,
        "compute": compute,
        "params": params,
    }


def _check_version(d: Path, manifest: Mapping[str, Any]) -> None:
    """Refuses a directory written in another version of the output format (its part-files have
    other columns: they can be neither resumed nor read as this version's table)."""
    version = manifest.get("version")
    if version != FORMAT_VERSION:
        raise SweepError(
            f"{d} holds a sweep in output format version {version!r}, written by another "
            f"version of capalloc_rs (this one writes version {FORMAT_VERSION}, whose columns "
            "are named by the results' to_dict() keys): read or resume it with the version "
            "that wrote it, or start afresh in another directory (or with resume=False)"
        )


def _same_type(a: Any, b: Any) -> bool:
    """Arrow types equal up to the names of list items (Parquet writes ``element``)."""
    pa = arrow()
    if pa.types.is_list(a) and pa.types.is_list(b):
        return _same_type(a.value_type, b.value_type)
    return bool(a.equals(b))


def _check_schema(path: Path, have: pa.Schema, sch: pa.Schema, compute: str) -> None:
    """A part-file's schema must be the sweep's (same columns, same types, same order)."""
    if have.names == sch.names and all(
        _same_type(have.field(k).type, sch.field(k).type) for k in sch.names
    ):
        return
    diff = (
        sorted(set(have.names) ^ set(sch.names))[:4]
        or [k for k in sch.names if not _same_type(have.field(k).type, sch.field(k).type)][:4]
    )
    raise SweepError(
        f"the part-file {path} has another schema than this {compute} sweep (differing "
        f"columns {diff}); it is not from this sweep: move it away"
    )


def _check_sweep_id(path: Path, have: pa.Schema, manifest: Mapping[str, Any]) -> None:
    """A part-file must carry the manifest's sweep identity (directories of versions before the
    identity have none, and are not checked)."""
    want_id = manifest.get(SWEEP_ID)
    if not want_id:
        return
    got_id = (have.metadata or {}).get(SWEEP_ID.encode(), b"").decode("utf-8", "replace")
    if got_id != want_id:
        raise SweepError(
            f"the part-file {path} belongs to another sweep (id {got_id or 'none'!r}, this "
            f"sweep's is {want_id!r}): it is not a task of this sweep; move it away"
        )


def _check_ids(path: Path, t: pa.Table, compute: str, params: Mapping[str, Any]) -> None:
    """Every task id of a part-file must be the one its row's id columns give."""
    for tid, idx, r, dig in zip(*(t.column(c).to_pylist() for c in _ID_COLUMNS), strict=True):
        if None in (tid, idx, r, dig) or tid != task_id(idx, r, compute, params, dig):
            raise SweepError(
                f"the part-file {path} holds the task id {tid!r}, which is not a task of this "
                f"sweep (compute={compute!r}, params={dict(params)!r}): it is not from this "
                "sweep: move it away"
            )


def check_part(path: Path, sch: pa.Schema, manifest: Mapping[str, Any]) -> pa.Table:
    """The id columns of the part-file ``path`` after checking that it belongs to the sweep of
    ``manifest`` (see the module docstring).

    Raises:
        SweepError: the file is damaged, or not a part of this sweep.
    """
    pa = arrow()
    compute, params = str(manifest["compute"]), manifest["params"]
    try:
        have = pa.parquet.read_schema(path)
    except (OSError, pa.ArrowException) as exc:
        raise SweepError(
            f"the part-file {path} is damaged or not Parquet ({exc}); delete it to recompute "
            "its tasks"
        ) from None
    _check_schema(path, have, sch, compute)
    _check_sweep_id(path, have, manifest)
    try:
        t = pa.parquet.read_table(path, columns=_ID_COLUMNS)
    except (OSError, pa.ArrowException) as exc:
        raise SweepError(f"the part-file {path} is damaged ({exc}); delete it") from None
    _check_ids(path, t, compute, params)
    return t


def _clean_debris(out: Path, token: str) -> None:
    """Removes the temporary files of interrupted writes: this process's own, or those of a
    process of this host that no longer runs (never a running sweep's)."""
    for tmp in out.glob(_TMP_PREFIX + "*"):
        if is_dead_debris(tmp.name, _TMP_PREFIX, token):
            with contextlib.suppress(OSError):
                tmp.unlink()


def _read_manifest(man: Path) -> dict[str, Any]:
    """The manifest ``man`` as a dict (resuming needs a readable one)."""
    try:
        have = json.loads(man.read_text())
    except (OSError, ValueError) as exc:
        raise SweepError(f"{man} is unreadable ({exc}); remove it or use resume=False") from None
    if not isinstance(have, dict):
        raise SweepError(f"{man} is not a sweep manifest; remove it or use resume=False")
    return have


def _resumed_id(out: Path, want: Mapping[str, Any]) -> str | None:
    """The identity of the sweep in ``out`` after checking that it is the sweep ``want``."""
    have = _read_manifest(out / MANIFEST)
    _check_version(out, have)
    same = {k: v for k, v in have.items() if k != SWEEP_ID}
    if same != json.loads(json.dumps(want)):
        raise SweepError(
            f"{out} holds a different sweep (compute={have.get('compute')!r}, "
            f"params={have.get('params')!r}); use another directory or resume=False"
        )
    got = have.get(SWEEP_ID)
    return None if got is None else str(got)  # None: a directory of an earlier version


def prepare_out(
    out: Path, compute: str, params: dict[str, Any], resume: bool, token: str
) -> tuple[set[str], str]:
    """Checks ``out`` (created and locked by the caller); returns the ids of the tasks already
    finished there and the sweep's identity (kept on resume, new otherwise; every part-file
    carries it in its metadata).

    Raises:
        SweepError: ``out`` holds another sweep, an unreadable manifest, part-files without a
            manifest, or a part-file that is not of this sweep.
    """
    _clean_debris(out, token)
    want = _manifest(compute, params)
    parts = sorted(out.glob(PART_GLOB))
    if not resume:
        for p in parts:
            p.unlink()
        parts = []
    elif (out / MANIFEST).exists():
        want[SWEEP_ID] = _resumed_id(out, want)
    elif parts:
        raise SweepError(f"{out} has part-files but no {MANIFEST}; use resume=False to overwrite")
    if not want.get(SWEEP_ID) and not parts:
        want[SWEEP_ID] = uuid.uuid4().hex
    _atomic_write_text(out / MANIFEST, json.dumps(want, indent=2, sort_keys=True) + "\n", token)
    done: set[str] = set()
    sch = schema(compute)
    for p in parts:
        done.update(check_part(p, sch, want).column("task_id").to_pylist())
    return done, str(want.get(SWEEP_ID) or "")


def _fsync_dir(d: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(d, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _atomic_write_text(path: Path, text: str, token: str) -> None:
    tmp = path.with_name(tmp_name(_TMP_PREFIX, f"{token}{uuid.uuid4().hex[:8]}", ".json"))
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def write_part(out: Path, table: pa.Table, token: str, sweep_id: str) -> Path:
    """Writes ``table`` atomically as a new part-file of ``out``; returns its path."""
    pq = arrow().parquet
    if sweep_id:
        table = table.replace_schema_metadata({SWEEP_ID: sweep_id})
    first = table.column("task_id")[0].as_py()
    name = f"part-{first}-{uuid.uuid4().hex[:8]}.parquet"
    tmp = out / tmp_name(_TMP_PREFIX, f"{token}{uuid.uuid4().hex[:8]}", f"-{name}")
    with open(tmp, "wb") as fh:
        pq.write_table(table, fh)
        fh.flush()
        os.fsync(fh.fileno())
    final = out / name
    os.replace(tmp, final)
    _fsync_dir(out)
    return final


def read_parts(out: Path, sch: pa.Schema) -> list[pa.Table]:
    """Every part-file of ``out``, read with the sweep's schema."""
    pa = arrow()
    tables = []
    for p in sorted(out.glob(PART_GLOB)):
        try:
            tables.append(pa.parquet.read_table(p, schema=sch))
        except (OSError, pa.ArrowException) as exc:
            raise SweepError(f"the part-file {p} is damaged ({exc}); delete it") from None
    return tables


def _valid_manifest(d: Path) -> tuple[dict[str, Any], pa.Schema]:
    """The manifest of the sweep directory ``d`` and its schema."""
    man = d / MANIFEST
    if not man.exists():
        raise SweepError(f"{d} is not a sweep output directory (no {MANIFEST})")
    try:
        have = json.loads(man.read_text())
        compute, params = have["compute"], have["params"]
        sch = schema(str(compute))
        if not isinstance(params, dict):
            raise TypeError("params is not a table")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SweepError(f"{man} is not a valid sweep manifest ({exc})") from None
    _check_version(d, have)
    return have, sch


def read_results(out: str | os.PathLike[str]) -> pa.Table:
    """Every row saved in a sweep's output directory, one per task id, sorted by task id.

    Args:
        out: the directory a sweep wrote with ``out=``.

    Returns:
        The :class:`pyarrow.Table` of the saved rows.

    Raises:
        SweepError: ``out`` is not a sweep's directory (no readable manifest), or a part-file is
            damaged, has another schema or holds tasks of another sweep (refused, not merged).
        MissingDependencyError: pyarrow is not installed.
    """
    pa = arrow()
    d = Path(out)
    have, sch = _valid_manifest(d)
    for p in sorted(d.glob(PART_GLOB)):
        check_part(p, sch, have)
    tables = read_parts(d, sch)
    return finish(pa.concat_tables(tables) if tables else sch.empty_table(), None)


def finish(table: pa.Table, keep: set[str] | None) -> pa.Table:
    """Keeps the rows of ``keep`` (all if ``None``), one per task id, sorted by task id."""
    pa = arrow()
    ids = table.column("task_id").to_pylist()
    seen: set[str] = set()
    idx = []
    for k, t in enumerate(ids):
        if (keep is None or t in keep) and t not in seen:
            seen.add(t)
            idx.append(k)
    table = table.take(pa.array(idx, type=pa.int64()))
    return table.sort_by("task_id").combine_chunks()
