"""Compiled programs kept across processes: the fit's jitted functions compiled ahead of time.

JAX's persistent compilation cache (:func:`brdffit.util.jax_config.enable_compilation_cache`)
skips XLA's compile in a new process, but not the Python tracing and the lowering to
StableHLO that compute its key: at 20,234 samples a fresh process spent about 1.4 s of a
1.6 s first walter fit tracing and lowering programs whose executables were on disk.

A :class:`Program` is ``eqx.filter_jit`` with a second, on-disk level: the first time a
configuration is met (the function, the static part of its arguments, the shapes and
dtypes of the arrays) it is traced, lowered and compiled once ahead of time, and the
executable is serialised (:mod:`jax.experimental.serialize_executable`) into the cache
folder; a later process loads it and calls it, so it is neither traced, lowered nor
looked up in XLA's cache again. Storing the exported StableHLO instead
(:func:`jax.export.export`), as this module did first, still lowered each program in
the new process and looked it up in XLA's cache: 65 and 121 ms of a 0.33 s first fit
at 20,234 samples, against 0.19-0.20 s for the whole fit now. One exception: an
executable that XLA's cache returned (the same program compiled before under another
key, such as an earlier version of brdffit's sources) serialises without its
functions on the CPU, and a later process that loads it fails to run it ("Function ...
not found"); such a program is stored as StableHLO, as before. Without the persistent cache
(the default for the Python API and the test suite) a :class:`Program` is a plain
``jax.jit`` of the flattened function.

A stored program is found by a key that names everything its code depends on: the
function's module and name, the tree structures and static values of the arguments
(their ``repr``: a model's options, a parameter table, a tolerance set), the array
shapes, dtypes and weak types, the jax and jaxlib versions, the backend, 64-bit mode,
``XLA_FLAGS`` and a fingerprint of brdffit's own source files (so an edited or upgraded
package never runs an old program). A configuration whose ``repr`` holds a memory
address (a closure, an object without a ``repr``) would never be found again, so it is
kept in memory only.

A stored program is called, never transformed: an executable carries no rule for
``jax.grad`` or ``jax.vmap`` of itself, so a :class:`Program` is for the engine's
host-side entry points (a descent, a start race, a covariance), not for functions a
user may differentiate or map over.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import pickle
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np
from jax.experimental import serialize_executable

from brdffit.util.atomic import write_atomic

log = logging.getLogger(__name__)

FOLDER = "programs"
"""Subfolder of the compilation cache's folder that holds the stored programs."""

EXECUTABLE = "executable"
"""A stored program's kind: XLA's executable, serialised; loads without lowering."""
EXPORTED = "exported"
"""A stored program's kind: the StableHLO module (:func:`jax.export.export`), lowered
again when loaded; for a program whose executable came from XLA's persistent cache."""

_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
_PACKAGE = Path(__file__).resolve().parents[1]


@dataclass
class _Entry:
    """One configuration's callable (flat arrays in, flat arrays out) and output tree."""

    call: Callable[..., tuple]
    out_tree: Any = None


class Program:
    """``fn`` compiled per static configuration and array shapes; stored on disk when the
    persistent compilation cache is on (module docstring).

    Arguments are split as ``eqx.filter_jit`` splits them: arrays (JAX or NumPy) are the
    program's inputs, everything else is static and must be hashable.
    """

    def __init__(self, fn: Callable[..., Any]):
        self.fn = fn
        self.name = f"{fn.__module__}.{fn.__qualname__}"
        self._entries: dict[tuple, _Entry] = {}
        functools.update_wrapper(self, fn)

    def __call__(self, *args: Any) -> Any:
        dyn, static = eqx.partition(args, eqx.is_array)
        leaves, in_tree = jax.tree.flatten(dyn)
        static_leaves, static_tree = jax.tree.flatten(static)
        avals = tuple(_aval(x) for x in leaves)
        key = (in_tree, static_tree, tuple(static_leaves), avals)
        entry = self._entries.get(key)
        if entry is None:
            entry = self._build(key, in_tree, static)
            self._entries[key] = entry
        out = entry.call(*leaves)
        return jax.tree.unflatten(entry.out_tree, out)

    def _build(self, key: tuple, in_tree: Any, static: Any) -> _Entry:
        trees: list[Any] = []

        def flat(*xs):
            out = self.fn(*eqx.combine(jax.tree.unflatten(in_tree, xs), static))
            ys, tree = jax.tree.flatten(out)
            trees.append(tree)
            return tuple(ys)

        flat.__name__ = flat.__qualname__ = self.fn.__name__  # names it in JAX's logs

        path = _stored_path(self.name, key)
        if path is None:
            entry = _Entry(jax.jit(flat))
            # the output tree is known once the function has been traced
            entry.call = _learn_tree(entry, entry.call, trees)
            return entry
        stored = _read(path, len(key[3]))
        if stored is not None:
            entry = _Entry(*stored)
            entry.call = _checked(entry, entry.call, jax.jit(flat), path)
            return entry
        structs = [jax.ShapeDtypeStruct(s, d, weak_type=w) for s, d, w in key[3]]
        compiled, fresh = _compile(jax.jit(flat).lower(*structs))
        out_tree = trees[-1]
        if fresh:
            _write(path, EXECUTABLE, serialize_executable.serialize(compiled)[0], out_tree)
        else:  # an executable from XLA's cache does not serialise whole (module docstring)
            exported = jax.export.export(jax.jit(flat))(*structs)
            _write(path, EXPORTED, bytes(exported.serialize()), out_tree)
        return _Entry(compiled, out_tree)


def program(fn: Callable[..., Any]) -> Program:
    """Decorator: ``fn`` as a :class:`Program`."""
    return Program(fn)


def _learn_tree(entry: _Entry, call: Callable[..., tuple], trees: list) -> Callable[..., tuple]:
    def first(*xs):
        out = call(*xs)
        entry.out_tree, entry.call = trees[-1], call
        return out

    return first


def _checked(
    entry: _Entry, loaded: Callable[..., tuple], fallback: Callable[..., tuple], path: Path
) -> Callable[..., tuple]:
    """``loaded`` (a stored program) for ``entry``, but if its first call fails in XLA's
    runtime (an executable that loads and cannot run, such as one that serialised
    without its functions), the file is removed and ``fallback`` (the function compiled
    in this process) runs instead, now and from then on."""

    def first(*xs):
        try:
            out = loaded(*xs)
        except jax.errors.JaxRuntimeError as err:
            log.warning("stored program %s failed to run (%s); compiling it again", path, err)
            path.unlink(missing_ok=True)
            entry.call = fallback
            return fallback(*xs)
        entry.call = loaded
        return out

    return first


def _aval(x: Any) -> tuple[tuple[int, ...], np.dtype, bool]:
    """(shape, dtype, weak type) of an array argument (JAX or NumPy: both carry a NumPy
    ``dtype``, which hashes and prints as its name does, at a tenth of the cost of
    looking the name up on every call)."""
    return tuple(x.shape), x.dtype, bool(getattr(x, "weak_type", False))


def store_folder() -> Path | None:
    """Where compiled programs are kept: ``programs/`` in the persistent compilation
    cache's folder, or ``None`` while that cache is off."""
    cache = jax.config.jax_compilation_cache_dir
    return Path(cache) / FOLDER if cache else None


def _stored_path(name: str, key: tuple) -> Path | None:
    folder = store_folder()
    if folder is None:
        return None
    text = repr((name, key, _environment()))
    if _ADDRESS.search(text):
        return None
    digest = hashlib.sha256(text.encode()).hexdigest()[:32]
    return folder / f"{name.rsplit('.', 1)[-1]}-{digest}.pkl"


@functools.cache
def _environment() -> tuple:
    """What a stored program's code depends on besides its own key."""
    from importlib import metadata

    try:
        jaxlib = metadata.version("jaxlib")
    except metadata.PackageNotFoundError:
        jaxlib = "unknown"
    return (
        jax.__version__,
        jaxlib,
        jax.default_backend(),
        bool(jax.config.jax_enable_x64),
        os.environ.get("XLA_FLAGS", ""),
        source_fingerprint(),
    )


@functools.cache
def source_fingerprint() -> str:
    """SHA-256 of brdffit's own ``.py`` files (relative path and content, in path order)."""
    h = hashlib.sha256()
    for path in sorted(_PACKAGE.rglob("*.py")):
        h.update(str(path.relative_to(_PACKAGE)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def _read(path: Path, n_args: int) -> tuple[Callable[..., tuple], Any] | None:
    """The program stored at ``path``, ready to call (a function of ``n_args`` flat arrays
    returning a flat tuple), and the original function's output tree; ``None`` when
    absent or unreadable (a damaged file is then written again)."""
    try:
        with open(path, "rb") as f:
            kind, blob, n_out, template = pickle.load(f)
        if kind == EXECUTABLE:
            _lapack_ready()
            in_tree = jax.tree.structure((tuple(range(n_args)), {}))
            out_tree = jax.tree.structure(tuple(range(n_out)))
            call = serialize_executable.deserialize_and_load(blob, in_tree, out_tree)
        else:
            call = jax.jit(jax.export.deserialize(bytearray(blob)).call)
        return call, jax.tree.structure(template)
    except FileNotFoundError:
        return None
    except (OSError, EOFError, pickle.UnpicklingError, ValueError, TypeError, RuntimeError) as err:
        log.warning("stored program %s unreadable (%s); compiling it again", path, err)
        return None


def _compile(lowered: jax.stages.Lowered) -> tuple[jax.stages.Compiled, bool]:
    """``lowered`` compiled, and whether XLA compiled it here (``False``: its executable
    came from XLA's persistent cache, told by the cache-hit event JAX records in the
    compiling thread)."""
    _listening()
    before = getattr(_HITS, "n", 0)
    compiled = lowered.compile()
    return compiled, getattr(_HITS, "n", 0) == before


_HITS = threading.local()
"""Per thread: how many of its compiles XLA's persistent cache answered."""


@functools.cache
def _listening() -> None:
    """Count XLA's cache hits per thread (:data:`_HITS`), from the first compile on."""

    def on_event(event: str, **_: Any) -> None:
        if event == "/jax/compilation_cache/cache_hits":
            _HITS.n = getattr(_HITS, "n", 0) + 1

    jax.monitoring.register_event_listener(on_event)


@functools.cache
def _lapack_ready() -> None:
    """Register LAPACK's kernels with XLA, once per process, before a stored executable
    runs.

    jaxlib registers them lazily, when a program that uses them (a Cholesky solve) is
    lowered; a loaded executable was not lowered in this process, and calling one before
    that registration crashes the process (a segmentation fault).
    :func:`jax.export.deserialize` makes the same call for the same reason; where a
    later JAX moves it, lowering a 1 x 1 Cholesky does it through the public API (0.13 s
    in a fresh process instead of nothing extra).
    """
    try:
        from jax._src.lax.linalg import initialize_lapack
    except ImportError:
        jax.jit(jax.numpy.linalg.cholesky).lower(jax.ShapeDtypeStruct((1, 1), np.float64))
    else:
        initialize_lapack()


def _write(path: Path, kind: str, blob: bytes, out_tree: Any) -> None:
    """Store a program (``kind`` :data:`EXECUTABLE` or :data:`EXPORTED`, serialised as
    ``blob``) and its output tree; a folder that cannot be written only costs the next
    process the compile again.

    The trees are stored as counts and as an example output whose leaves are their
    indices: a tree definition of equinox modules does not survive pickling, the modules
    themselves do.
    """
    template = jax.tree.unflatten(out_tree, range(out_tree.num_leaves))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, [pickle.dumps((kind, blob, out_tree.num_leaves, template))])
    except OSError as err:
        log.warning("could not store program %s: %s", path, err)
