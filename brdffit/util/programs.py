"""Compiled programs kept across processes: the fit's jitted functions exported ahead of time.

JAX's persistent compilation cache (:func:`brdffit.util.jax_config.enable_compilation_cache`)
skips XLA's compile in a new process, but not the Python tracing and the lowering to
StableHLO that compute its key: at 20,234 samples a fresh process spent about 1.4 s of a
1.6 s first walter fit tracing and lowering programs whose executables were on disk.

A :class:`Program` is ``eqx.filter_jit`` with a second, on-disk level: the first time a
configuration is met (the function, the static part of its arguments, the shapes and
dtypes of the arrays) it is traced once, exported with :func:`jax.export.export` (the
StableHLO module, serialised) and written into the cache folder, beside the executables;
a later process reads the module back and calls it, so it is neither traced nor lowered
again, and XLA's executable comes from the persistent cache. Without the persistent
cache (the default for the Python API and the test suite) a :class:`Program` is a plain
``jax.jit`` of the flattened function.

A stored program is found by a key that names everything its code depends on: the
function's module and name, the tree structures and static values of the arguments
(their ``repr``: a model's options, a parameter table, a tolerance set), the array
shapes, dtypes and weak types, the jax and jaxlib versions, the backend, 64-bit mode,
``XLA_FLAGS`` and a fingerprint of brdffit's own source files (so an edited or upgraded
package never runs an old program). A configuration whose ``repr`` holds a memory
address (a closure, an object without a ``repr``) would never be found again, so it is
kept in memory only.

A stored program is called, never transformed: an exported module carries no rule for
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
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import numpy as np

from brdffit.util.atomic import write_atomic

log = logging.getLogger(__name__)

FOLDER = "programs"
"""Subfolder of the compilation cache's folder that holds the exported programs."""

_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
_PACKAGE = Path(__file__).resolve().parents[1]


@dataclass
class _Entry:
    """One configuration's callable (flat arrays in, flat arrays out) and output tree."""

    call: Callable[..., tuple]
    out_tree: Any = None


class Program:
    """``fn`` compiled per static configuration and array shapes; exported to disk when the
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
        stored = _read(path)
        if stored is not None:
            exported, out_tree = stored
            return _Entry(jax.jit(exported.call), out_tree)
        structs = [jax.ShapeDtypeStruct(s, np.dtype(d), weak_type=w) for s, d, w in key[3]]
        exported = jax.export.export(jax.jit(flat))(*structs)
        _write(path, exported, trees[-1])
        return _Entry(jax.jit(exported.call), trees[-1])


def program(fn: Callable[..., Any]) -> Program:
    """Decorator: ``fn`` as a :class:`Program`."""
    return Program(fn)


def _learn_tree(entry: _Entry, call: Callable[..., tuple], trees: list) -> Callable[..., tuple]:
    def first(*xs):
        out = call(*xs)
        entry.out_tree, entry.call = trees[-1], call
        return out

    return first


def _aval(x: Any) -> tuple[tuple[int, ...], str, bool]:
    """(shape, dtype name, weak type) of an array argument."""
    return tuple(np.shape(x)), np.dtype(x.dtype).name, bool(getattr(x, "weak_type", False))


def store_folder() -> Path | None:
    """Where exported programs are kept: ``programs/`` in the persistent compilation
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


def _read(path: Path) -> tuple[jax.export.Exported, Any] | None:
    """The exported program and output tree stored at ``path``; ``None`` when absent or
    unreadable (a damaged file is then written again)."""
    try:
        with open(path, "rb") as f:
            blob, template = pickle.load(f)
        return jax.export.deserialize(bytearray(blob)), jax.tree.structure(template)
    except FileNotFoundError:
        return None
    except (OSError, EOFError, pickle.UnpicklingError, ValueError, TypeError) as err:
        log.warning("stored program %s unreadable (%s); exporting it again", path, err)
        return None


def _write(path: Path, exported: jax.export.Exported, out_tree: Any) -> None:
    """Store the program and its output tree; a folder that cannot be written only costs
    the next process the tracing again.

    The tree is stored as an example output whose leaves are their indices: a tree
    definition of equinox modules does not survive pickling, the modules themselves do.
    """
    template = jax.tree.unflatten(out_tree, range(out_tree.num_leaves))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, [pickle.dumps((bytes(exported.serialize()), template))])
    except OSError as err:
        log.warning("could not store program %s: %s", path, err)
